//! The files generated from the topic registry ([`proto::registry`]) must not drift from it: the
//! docs' key table and `deploy/certs.sh`'s access control. `SACLSP_BLESS=1 cargo test -p proto
//! --test registry` rewrites both.

use std::path::{Path, PathBuf};

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// Checks (or, blessing, rewrites) the lines of `path` strictly between the `begin` and `end`
/// marker lines.
fn generated(path: &str, begin: &str, end: &str, want: &str) {
    let file = repo(path);
    let text = std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{path}: {e}"));
    let start = text.find(begin).unwrap_or_else(|| panic!("{path} has no {begin:?} line"));
    let body = start + text[start..].find('\n').expect("a line after the marker") + 1;
    let stop = body + text[body..].find(end).unwrap_or_else(|| panic!("{path} has no {end:?} line"));
    if text[body..stop] == *want {
        return;
    }
    if std::env::var("SACLSP_BLESS").as_deref() == Ok("1") {
        std::fs::write(&file, format!("{}{want}{}", &text[..body], &text[stop..]))
            .unwrap_or_else(|e| panic!("{path}: {e}"));
        return;
    }
    panic!(
        "{path} drifted from proto's topic registry (SACLSP_BLESS=1 cargo test -p proto --test registry \
         rewrites it). Expected between the markers:\n{want}\nFound:\n{}",
        &text[body..stop]
    );
}

#[test]
fn the_docs_key_table_is_the_registry() {
    generated(
        "docs/distributed.md",
        "<!-- topics:begin -->",
        "<!-- topics:end -->",
        &proto::registry::markdown_table(),
    );
}

#[test]
fn certs_access_control_is_the_registry() {
    let acl = proto::registry::access_control();
    let list = |items: &[String]| items.iter().map(|i| format!("      {i}\n")).collect::<String>();
    let want = format!("rules='\n{}'\npolicies='\n{}'\n", list(&acl.rules), list(&acl.policies));
    generated("deploy/certs.sh", "# topics:begin", "# topics:end", &want);
}

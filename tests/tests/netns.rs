//! The cluster as real processes in two Linux network namespaces joined by a veth pair, as on two
//! machines: replay server, param server and learner in namespace A (10.213.0.1), two executors in
//! namespace B (10.213.0.2) that only know A's endpoint. The learner is told to stop after 200
//! updates, which it can only reach if B's transitions cross the link; every wait has a deadline.
//! Needs root and `ip` (CI has both); elsewhere it says so and passes without running.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const MAX_UPDATES: u64 = 200;

struct Namespaces {
    a: String,
    b: String,
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip").args(args).output().map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim()))
    }
}

impl Namespaces {
    fn create() -> Result<Namespaces, String> {
        let tag = std::process::id() % 100_000;
        let ns = Namespaces { a: format!("sacA{tag}"), b: format!("sacB{tag}") };
        let (va, vb) = (format!("vsa{tag}"), format!("vsb{tag}"));
        ip(&["netns", "add", &ns.a])?;
        ip(&["netns", "add", &ns.b])?;
        ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
        ip(&["link", "set", &va, "netns", &ns.a])?;
        ip(&["link", "set", &vb, "netns", &ns.b])?;
        ip(&["-n", &ns.a, "addr", "add", "10.213.0.1/24", "dev", &va])?;
        ip(&["-n", &ns.b, "addr", "add", "10.213.0.2/24", "dev", &vb])?;
        for (n, v) in [(&ns.a, &va), (&ns.b, &vb)] {
            ip(&["-n", n, "link", "set", v, "up"])?;
            ip(&["-n", n, "link", "set", "lo", "up"])?;
        }
        Ok(ns)
    }
}

impl Drop for Namespaces {
    fn drop(&mut self) {
        // Deleting a namespace deletes its end of the veth pair, and with it the other end.
        let _ = ip(&["netns", "del", &self.a]);
        let _ = ip(&["netns", "del", &self.b]);
    }
}

struct Proc {
    name: String,
    child: Child,
    log: PathBuf,
}

impl Proc {
    fn start(ns: &str, name: &str, args: &[&str], dir: &Path) -> Proc {
        let log = dir.join(format!("{name}.log"));
        let file = std::fs::File::create(&log).expect("log file");
        let child = Command::new("ip")
            .args(["netns", "exec", ns, env!("CARGO_BIN_EXE_cluster-node")])
            .args(args)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(file)
            .spawn()
            .expect("spawn cluster-node");
        Proc { name: name.into(), child, log }
    }

    fn wait_exit(&mut self, limit: Duration) -> Option<std::process::ExitStatus> {
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        None
    }

    fn terminate(&mut self) -> Option<std::process::ExitStatus> {
        let _ = Command::new("kill").args(["-TERM", &self.child.id().to_string()]).status();
        self.wait_exit(Duration::from_secs(30))
    }

    fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The number after `field: ` in a `Debug`-printed report.
fn field(log: &str, field: &str) -> Option<u64> {
    let at = log.rfind(&format!("{field}: "))? + field.len() + 2;
    log[at..].chars().take_while(char::is_ascii_digit).collect::<String>().parse().ok()
}

#[test]
fn executors_in_another_namespace_feed_the_learner() {
    let is_root = Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout.starts_with(b"0"));
    if !is_root {
        eprintln!("skipped: needs root for ip netns");
        return;
    }
    let ns = match Namespaces::create() {
        Ok(ns) => ns,
        Err(why) => {
            eprintln!("skipped: cannot create network namespaces here: {why}");
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("netns-run-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("run.toml");
    let spec = cluster::Spec::tiny("netns", 2);
    std::fs::write(
        &config,
        format!("{}\n", spec.config.replace("[learner]", &format!("[learner]\nmax_updates = {MAX_UPDATES}"))),
    )
    .unwrap();
    let config = config.to_str().unwrap();
    let common = ["--run-id", "netns", "--config", config];
    let hub = "tcp/10.213.0.1:7447";
    let mut procs = Vec::new();
    let mut start = |ns: &str, name: &str, role: &str, extra: &[&str]| {
        let mut args = vec![role];
        args.extend_from_slice(&common);
        args.extend_from_slice(extra);
        procs.push(Proc::start(ns, name, &args, &dir));
    };
    start(&ns.a, "replay", "replay", &["--listen", hub]);
    start(&ns.a, "param", "param", &["--connect", hub, "--listen", "tcp/10.213.0.1:0"]);
    start(&ns.a, "learner", "learner", &["--connect", hub, "--listen", "tcp/10.213.0.1:0"]);
    for id in ["0", "1"] {
        let name = format!("executor-{id}");
        start(&ns.b, &name, "executor", &["--id", id, "--connect", hub, "--listen", "tcp/10.213.0.2:0"]);
    }
    // The learner stops by itself after MAX_UPDATES, which needs B's experience.
    let learner_exit = procs[2].wait_exit(Duration::from_secs(240));
    let mut statuses = Vec::new();
    for p in procs.iter_mut().rev() {
        let status = if p.name == "learner" { learner_exit } else { p.terminate() };
        statuses.push((p.name.clone(), status, p.log_text()));
    }
    let dump =
        || statuses.iter().map(|(n, s, log)| format!("--- {n} ({s:?})\n{}", tail(log))).collect::<String>();
    for (name, status, _) in &statuses {
        assert!(status.is_some_and(|s| s.success()), "{name} did not exit cleanly\n{}", dump());
    }
    let log = |name: &str| statuses.iter().find(|(n, _, _)| n == name).map(|(_, _, l)| l.clone()).unwrap();
    assert_eq!(field(&log("learner"), "final_step"), Some(MAX_UPDATES), "{}", dump());
    for id in 0..2 {
        let l = log(&format!("executor-{id}"));
        assert!(
            field(&l, "weights_fetched").is_some_and(|n| n >= 1),
            "executor {id} got no weights\n{}",
            dump()
        );
        assert!(
            field(&l, "batches_published").is_some_and(|n| n >= 1),
            "executor {id} sent nothing\n{}",
            dump()
        );
    }
    drop(ns);
    let _ = std::fs::remove_dir_all(&dir);
}

fn tail(log: &str) -> String {
    let lines: Vec<&str> = log.lines().collect();
    lines[lines.len().saturating_sub(15)..].join("\n")
}

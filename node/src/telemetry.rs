//! Tracing set-up shared by every binary: human-readable lines on stderr, filtered by `RUST_LOG`
//! (default `info`). Each role enters a span carrying its name and id, so the lines of four roles in
//! one process (the test harness) stay readable.

/// Installs the global subscriber once; later calls (tests, several roles in one process) do nothing.
pub fn init() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).try_init();
}

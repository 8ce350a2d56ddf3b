//! The live text view: one screen redrawn every interval, so a stalled run shows where it stalls
//! (who is blocked on what, who rejects what, who is dead).

use std::fmt::Write;

use proto::{NodeId, Role};

use super::family::Family;
use super::state::{MonitorState, node_name};
use super::tick::Tick;

/// ANSI: clear the screen and move the cursor home.
pub const CLEAR: &str = "\x1b[2J\x1b[H";

/// The screen for `tick` (no clear sequence; the caller adds it).
pub fn render(state: &MonitorState, tick: &Tick) -> String {
    let mut s = String::new();
    // Writing to a String cannot fail; the results are ignored for readability.
    let _ = write_screen(&mut s, state, tick);
    s
}

/// One plain status line for logs and pipes (no terminal control): the figures of the screen's
/// first lines, the dead and the blocked.
pub fn line(state: &MonitorState, tick: &Tick) -> String {
    let learner = |name: &str| state.role_metric(Role::Learner, name);
    let dead = tick.executors.iter().filter(|e| e.alive == Some(false)).count();
    let eval = state.last_eval().map(|e| e.mean_return);
    format!(
        "up {} | learner step {} {} updates/s | env steps {} {}/s | replay {} | executors {} ({dead} dead, {} blocked entries) | returns {} | recent return {} | eval {}",
        clock(tick.now.elapsed_s),
        int(tick.learner_step),
        num(learner("learner/updates_per_s")),
        int(tick.env_steps_total),
        num(tick.env_steps_per_s_total),
        num(tick.replay_size),
        tick.executors.len(),
        tick.blocked.len(),
        state.returns_total(),
        num(state.recent_return().map(|r| r.mean)),
        num(eval),
    )
}

fn write_screen(s: &mut String, state: &MonitorState, tick: &Tick) -> std::fmt::Result {
    let learner = |name: &str| state.role_metric(Role::Learner, name);
    let replay = |name: &str| state.role_metric(Role::Replay, name);
    let param = |name: &str| state.role_metric(Role::Param, name);
    writeln!(s, "sac-lsp monitor | run {} | up {}", state.run(), clock(tick.now.elapsed_s))?;
    writeln!(s)?;
    match state.last_step() {
        Some(g) => writeln!(
            s,
            "global step   learner {}  weights {}  live executors {}  warm-up share {}",
            g.learner_step, g.weights_version, g.live_executors, g.warm_up_share
        )?,
        None => writeln!(s, "global step   (no announcement yet)")?,
    }
    writeln!(
        s,
        "learner       step {}  {} updates/s  q {}  v {}  policy {}  waiting {}  eval {}",
        int(tick.learner_step),
        num(learner("learner/updates_per_s")),
        num(learner("learner/q_loss")),
        num(learner("learner/v_loss")),
        num(learner("learner/policy_loss")),
        percent(learner("learner/wait_fraction")),
        num(learner("learner/eval_return")),
    )?;
    writeln!(
        s,
        "replay        size {}  {} inserts/s  {} batches/s",
        num(replay("replay/size_transitions")),
        num(replay("replay/inserts_per_s")),
        num(replay("replay/batches_per_s")),
    )?;
    writeln!(
        s,
        "param server  weights {}  live executors {}",
        num(param("param/weights_version")),
        num(param("param/live_executors")),
    )?;
    writeln!(s)?;
    write_executors(s, tick)?;
    writeln!(s)?;
    match state.recent_return() {
        Some(r) => writeln!(s, "episodes      mean return of the last {}: {}", r.count, num(Some(r.mean)))?,
        None => writeln!(s, "episodes      (none yet)")?,
    }
    match state.last_eval() {
        Some(e) => writeln!(
            s,
            "evaluation    epoch {} at learner step {}: mean return {} over {} episode(s), length {}{}",
            e.epoch,
            e.learner_step,
            num(Some(e.mean_return)),
            e.episodes,
            num(Some(e.mean_length)),
            e.goal_success.map(|s| format!(", goal reached in {:.0}%", 100.0 * s)).unwrap_or_default(),
        )?,
        None => writeln!(s, "evaluation    (none yet)")?,
    }
    write_blocked(s, tick)?;
    write_rejected(s, state)?;
    write_nodes(s, state, tick)?;
    write_counts(s, state)
}

fn write_executors(s: &mut String, tick: &Tick) -> std::fmt::Result {
    writeln!(
        s,
        "{:>8} {:>6} {:>12} {:>10} {:>8} {:>8} {:>8} {:>12}",
        "executor", "alive", "env steps", "steps/s", "w-lag", "p-lag", "blocked", "last return"
    )?;
    for row in &tick.executors {
        writeln!(
            s,
            "{:>8} {:>6} {:>12} {:>10} {:>8} {:>8} {:>8} {:>12}",
            row.id,
            yes_no(row.alive, "alive", "DEAD"),
            int(row.env_steps),
            num(row.env_steps_per_s),
            num(row.weights_lag_steps),
            num(row.policy_lag_steps),
            yes_no(row.blocked, "BLOCKED", "no"),
            num(row.last_return),
        )?;
    }
    writeln!(
        s,
        "{:>8} {:>6} {:>12} {:>10}",
        "total",
        "",
        int(tick.env_steps_total),
        num(tick.env_steps_per_s_total)
    )
}

fn write_blocked(s: &mut String, tick: &Tick) -> std::fmt::Result {
    if tick.blocked.is_empty() {
        return Ok(());
    }
    writeln!(s, "blocked")?;
    for b in &tick.blocked {
        let since = tick.now.unix_ms.saturating_sub(b.since_ms) as f64 / 1000.0;
        writeln!(s, "  {:<12} {:<20} {} (for {})", b.node, b.what, b.why, clock(since))?;
    }
    Ok(())
}

fn write_rejected(s: &mut String, state: &MonitorState) -> std::fmt::Result {
    let mut header = false;
    for report in state.reports_sorted() {
        for r in report.rejected.iter().filter(|r| r.count > 0) {
            if !header {
                writeln!(s, "rejected")?;
                header = true;
            }
            writeln!(s, "  {:<12} {:<32} {}", node_name(report.node()), r.reason, r.count)?;
        }
    }
    Ok(())
}

/// Every reporting process with the age of its last report, so a silent one stands out.
fn write_nodes(s: &mut String, state: &MonitorState, tick: &Tick) -> std::fmt::Result {
    let nodes: Vec<String> = state
        .reports_sorted()
        .into_iter()
        .map(|r| {
            let age = tick.now.unix_ms.saturating_sub(r.unix_ms) as f64 / 1000.0;
            let node = NodeId { role: r.role, id: r.id };
            let dead = if state.is_alive(node) == Some(false) { " DEAD" } else { "" };
            let returns = match state.returns(node) {
                0 => String::new(),
                n => format!(" (back {n}x)"),
            };
            format!("{} {age:.1}s{dead}{returns}", node_name(r.node()))
        })
        .collect();
    if nodes.is_empty() {
        writeln!(s, "reports       (none yet: is the run id right, and the bus connected?)")
    } else {
        writeln!(s, "reports       {}", nodes.join(", "))
    }
}

fn write_counts(s: &mut String, state: &MonitorState) -> std::fmt::Result {
    let counts: Vec<String> =
        Family::ALL.iter().map(|f| format!("{f} {}", state.received().get(*f))).collect();
    writeln!(s, "received      {}", counts.join("  "))?;
    if state.undecodable().total() > 0 {
        let bad: Vec<String> = Family::ALL
            .iter()
            .filter(|f| state.undecodable().get(**f) > 0)
            .map(|f| format!("{f} {}", state.undecodable().get(*f)))
            .collect();
        writeln!(s, "UNDECODABLE   {}", bad.join("  "))?;
    }
    Ok(())
}

/// A figure with about four significant digits, or `-` when unknown.
fn num(value: Option<f64>) -> String {
    match value {
        None => "-".to_string(),
        Some(v) if v == v.trunc() && v.abs() < 1e15 => format!("{v:.0}"),
        Some(v) if v.abs() >= 100.0 => format!("{v:.1}"),
        Some(v) if v.abs() >= 0.01 => format!("{v:.3}"),
        Some(v) => format!("{v:.3e}"),
    }
}

fn int(value: Option<u64>) -> String {
    value.map_or_else(|| "-".to_string(), |v| v.to_string())
}

fn percent(value: Option<f64>) -> String {
    value.map_or_else(|| "-".to_string(), |v| format!("{:.1}%", v * 100.0))
}

fn yes_no(value: Option<bool>, yes: &str, no: &str) -> String {
    match value {
        Some(true) => yes.to_string(),
        Some(false) => no.to_string(),
        None => "?".to_string(),
    }
}

/// Seconds as `h:mm:ss` (or `m:ss`).
fn clock(seconds: f64) -> String {
    let total = seconds.max(0.0) as u64;
    let (h, m, s) = (total / 3600, total / 60 % 60, total % 60);
    if h > 0 { format!("{h}:{m:02}:{s:02}") } else { format!("{m}:{s:02}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_are_short_and_unknowns_are_dashes() {
        assert_eq!(num(None), "-");
        assert_eq!(num(Some(1200.0)), "1200");
        assert_eq!(num(Some(612.49)), "612.5");
        assert_eq!(num(Some(0.25)), "0.250");
        assert_eq!(num(Some(0.000123)), "1.230e-4");
        assert_eq!(percent(Some(0.125)), "12.5%");
        assert_eq!(clock(59.9), "0:59");
        assert_eq!(clock(3725.0), "1:02:05");
        assert_eq!(yes_no(None, "a", "b"), "?");
    }
}

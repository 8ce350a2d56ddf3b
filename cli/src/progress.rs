//! Progress of a long command on stderr: an `indicatif` bar on a terminal, and a plain line every
//! tenth of the work otherwise (logs and pipes get no control characters).

use std::io::IsTerminal;

use indicatif::{ProgressBar, ProgressStyle};

/// Progress over `len` units of work.
#[derive(Debug)]
pub struct Progress {
    bar: Option<ProgressBar>,
    what: &'static str,
    len: u64,
    done: u64,
}

impl Progress {
    /// Starts counting `len` units of `what` (e.g. "episodes").
    pub fn new(what: &'static str, len: u64) -> Progress {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::new(len);
            let template = format!("[{{bar:30}}] {{pos}}/{{len}} {what} ({{eta}} left) {{msg}}");
            if let Ok(style) = ProgressStyle::with_template(&template) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar
        });
        Progress { bar, what, len, done: 0 }
    }

    /// One more unit done; `message` says how things stand (e.g. the mean return so far).
    pub fn inc(&mut self, message: &str) {
        self.done += 1;
        match &self.bar {
            Some(bar) => {
                bar.set_message(message.to_string());
                bar.inc(1);
            }
            None => {
                if self.done.is_multiple_of((self.len / 10).max(1)) || self.done == self.len {
                    eprintln!("{}/{} {}: {message}", self.done, self.len, self.what);
                }
            }
        }
    }

    /// Clears the bar (plain lines stay).
    pub fn finish(self) {
        if let Some(bar) = self.bar {
            bar.finish_and_clear();
        }
    }
}

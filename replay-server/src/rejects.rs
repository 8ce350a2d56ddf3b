//! Bad input: a short reason for every way a message can be refused, counts by reason, and warnings
//! that stay readable in a flood (one line per reason per interval, with the count suppressed).

use proto::DecodeError;

/// Which input a rejected message arrived on; the prefix of its reason (`experience/checksum`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// `experience/*`.
    Experience,
    /// `replay/priorities`.
    Priorities,
    /// `replay/sample` queries.
    Sample,
}

impl Input {
    fn as_str(self) -> &'static str {
        match self {
            Input::Experience => "experience",
            Input::Priorities => "priorities",
            Input::Sample => "sample",
        }
    }
}

/// One refused message: the input, a short reason, and the details for the log.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejection {
    /// The input it arrived on.
    pub input: Input,
    /// Short reason (`checksum`, `dims`, ...).
    pub reason: &'static str,
    /// Human-readable details.
    pub detail: String,
}

impl Rejection {
    /// A rejection for a decode error.
    pub fn decode(input: Input, error: &DecodeError) -> Self {
        Self { input, reason: error.reason(), detail: error.to_string() }
    }

    /// The counter key, `<input>/<reason>`.
    pub fn key(&self) -> String {
        format!("{}/{}", self.input.as_str(), self.reason)
    }
}

pub use node::Rejects;

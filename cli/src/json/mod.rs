//! A minimal JSON value: enough to write the monitor's JSONL record and read it back for plotting.
//!
//! Written by hand because no JSON crate is a dependency of the workspace; the format is small and
//! the record is ours, so a compact writer ([`std::fmt::Display`]) and a strict parser ([`parse`])
//! cover it.

mod parse;
mod write;

pub use parse::parse;

/// One JSON value. Numbers keep unsigned integers exact ([`Value::UInt`]); everything else that is
/// a number is an `f64` ([`Value::Float`], written as `null` when not finite).
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// `null`: also what a missing figure is written as.
    Null,
    /// `true` / `false`.
    Bool(bool),
    /// A non-negative integer literal (counters, steps, Unix milliseconds).
    UInt(u64),
    /// Any other number.
    Float(f64),
    /// A string.
    Str(String),
    /// An array.
    Array(Vec<Value>),
    /// An object.
    Object(Object),
}

/// A JSON object that keeps its fields in insertion order, so records read well (`"type"` first).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Object {
    fields: Vec<Field>,
}

/// One `"key": value` member of an [`Object`].
#[derive(Debug, Clone, PartialEq)]
struct Field {
    key: String,
    value: Value,
}

impl Object {
    /// An empty object.
    pub fn new() -> Object {
        Object::default()
    }

    /// Appends a field (builder style).
    pub fn with(mut self, key: &str, value: impl Into<Value>) -> Object {
        self.fields.push(Field { key: key.to_string(), value: value.into() });
        self
    }

    /// The value of the first field called `key`.
    pub fn get(&self, key: &str) -> Option<&Value> {
        self.fields.iter().find(|f| f.key == key).map(|f| &f.value)
    }
}

impl Value {
    /// The field `key` if this is an object.
    pub fn get(&self, key: &str) -> Option<&Value> {
        match self {
            Value::Object(object) => object.get(key),
            _ => None,
        }
    }

    /// The number, if this is one (`null` is not).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::UInt(n) => Some(*n as f64),
            Value::Float(x) => Some(*x),
            _ => None,
        }
    }

    /// The number as an exact unsigned integer, if it is one.
    pub fn as_u64(&self) -> Option<u64> {
        match self {
            Value::UInt(n) => Some(*n),
            _ => None,
        }
    }

    /// The string, if this is one.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The elements, if this is an array.
    #[cfg(test)]
    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Array(items) => Some(items),
            _ => None,
        }
    }

    /// The boolean, if this is one.
    #[cfg(test)]
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    }
}

impl From<bool> for Value {
    fn from(b: bool) -> Value {
        Value::Bool(b)
    }
}

impl From<u64> for Value {
    fn from(n: u64) -> Value {
        Value::UInt(n)
    }
}

impl From<u32> for Value {
    fn from(n: u32) -> Value {
        Value::UInt(u64::from(n))
    }
}

impl From<f64> for Value {
    fn from(x: f64) -> Value {
        Value::Float(x)
    }
}

impl From<&str> for Value {
    fn from(s: &str) -> Value {
        Value::Str(s.to_string())
    }
}

impl From<String> for Value {
    fn from(s: String) -> Value {
        Value::Str(s)
    }
}

impl From<Object> for Value {
    fn from(object: Object) -> Value {
        Value::Object(object)
    }
}

impl From<Vec<Value>> for Value {
    fn from(items: Vec<Value>) -> Value {
        Value::Array(items)
    }
}

/// `None` is written as `null`: a figure nobody has reported yet.
impl<T: Into<Value>> From<Option<T>> for Value {
    fn from(value: Option<T>) -> Value {
        value.map_or(Value::Null, Into::into)
    }
}

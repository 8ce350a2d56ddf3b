//! Compact JSON text: one line per value, so a record file is JSONL.

use std::fmt::{self, Write};

use super::{Object, Value};

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Null => f.write_str("null"),
            Value::Bool(b) => write!(f, "{b}"),
            Value::UInt(n) => write!(f, "{n}"),
            // `{}` on f64 is the shortest text that parses back to the same value and never uses an
            // exponent, so it is always a valid JSON number; JSON has no NaN or infinity.
            Value::Float(x) if x.is_finite() => write!(f, "{x}"),
            Value::Float(_) => f.write_str("null"),
            Value::Str(s) => write_string(f, s),
            Value::Array(items) => {
                f.write_char('[')?;
                for (i, item) in items.iter().enumerate() {
                    if i > 0 {
                        f.write_char(',')?;
                    }
                    write!(f, "{item}")?;
                }
                f.write_char(']')
            }
            Value::Object(object) => write!(f, "{object}"),
        }
    }
}

impl fmt::Display for Object {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_char('{')?;
        for (i, field) in self.fields.iter().enumerate() {
            if i > 0 {
                f.write_char(',')?;
            }
            write_string(f, &field.key)?;
            write!(f, ":{}", field.value)?;
        }
        f.write_char('}')
    }
}

/// A JSON string literal: quotes, backslashes and control characters escaped (RFC 8259 §7).
fn write_string(f: &mut fmt::Formatter<'_>, s: &str) -> fmt::Result {
    f.write_char('"')?;
    for c in s.chars() {
        match c {
            '"' => f.write_str("\\\"")?,
            '\\' => f.write_str("\\\\")?,
            '\n' => f.write_str("\\n")?,
            '\r' => f.write_str("\\r")?,
            '\t' => f.write_str("\\t")?,
            c if u32::from(c) < 0x20 => write!(f, "\\u{:04x}", u32::from(c))?,
            c => f.write_char(c)?,
        }
    }
    f.write_char('"')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_round_trip_and_non_finite_is_null() {
        let object = Object::new()
            .with("a", 0.1)
            .with("b", 1.0e-7)
            .with("c", f64::NAN)
            .with("d", f64::NEG_INFINITY)
            .with("e", u64::MAX)
            .with("f", None::<f64>)
            .with("g", -2.5);
        assert_eq!(
            object.to_string(),
            r#"{"a":0.1,"b":0.0000001,"c":null,"d":null,"e":18446744073709551615,"f":null,"g":-2.5}"#
        );
    }

    #[test]
    fn strings_are_escaped() {
        let v = Value::from("a\"b\\c\nd\u{1}é");
        assert_eq!(v.to_string(), r#""a\"b\\c\nd\u0001é""#);
        let nested = Value::from(vec![Value::from(true), Value::Null, Object::new().with("k", "v").into()]);
        assert_eq!(nested.to_string(), r#"[true,null,{"k":"v"}]"#);
    }
}

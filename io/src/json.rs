//! A compact JSON tree for scene files.
//!
//! `serde_json::Value` keeps every object in a `BTreeMap`, whose smallest node
//! holds room for 11 entries: a sphere `{"sphere": {"center": [...], "radius":
//! r}}` took about 1.4 KB, most of the io side's 3.7 KB per leaf on a
//! 1 000 000-sphere union. Here an object is a boxed slice of its members in
//! file order and a value is 24 bytes, so the same sphere takes about 200 bytes.
//! Lookups are linear scans, which is what objects of a few keys want; the
//! parser asks a constant number of them per object.

use serde::de::{Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};

/// A JSON number, as written: an integer stays an integer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Number {
    /// A non-negative integer.
    U(u64),
    /// A negative integer.
    I(i64),
    /// Anything else.
    F(f64),
}

/// A JSON value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `null`.
    Null,
    /// `true` or `false`.
    Bool(bool),
    /// A number.
    Number(Number),
    /// A string.
    String(Box<str>),
    /// An array.
    Array(Box<[Value]>),
    /// An object.
    Object(Map),
}

/// A JSON object: its members in file order. A repeated key keeps its last
/// value (as `serde_json` does) for lookups.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Map(Box<[(Box<str>, Value)]>);

static NULL: Value = Value::Null;

impl Map {
    /// The value of member `k` (the last one if repeated).
    pub fn get(&self, k: &str) -> Option<&Value> {
        self.0.iter().rev().find(|(key, _)| &**key == k).map(|(_, v)| v)
    }
    /// Is there a member `k`?
    pub fn contains_key(&self, k: &str) -> bool {
        self.get(k).is_some()
    }
    /// Member names in file order.
    pub fn keys(&self) -> impl Iterator<Item = &str> {
        self.0.iter().map(|(k, _)| &**k)
    }
    /// Number of members.
    pub fn len(&self) -> usize {
        self.0.len()
    }
    /// No members?
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl std::ops::Index<&str> for Map {
    type Output = Value;
    /// `null` for a missing member, never a panic.
    fn index(&self, k: &str) -> &Value {
        self.get(k).unwrap_or(&NULL)
    }
}

impl std::ops::Index<usize> for Value {
    type Output = Value;
    /// `null` past the end or on a non-array, never a panic.
    fn index(&self, i: usize) -> &Value {
        match self {
            Value::Array(a) => a.get(i).unwrap_or(&NULL),
            _ => &NULL,
        }
    }
}

impl Value {
    /// The members, if an object.
    pub fn as_object(&self) -> Option<&Map> {
        match self {
            Value::Object(m) => Some(m),
            _ => None,
        }
    }
    /// The elements, if an array.
    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Array(a) => Some(a),
            _ => None,
        }
    }
    /// The text, if a string.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(s) => Some(s),
            _ => None,
        }
    }
    /// The number as f64, if a number.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Number(Number::U(u)) => Some(*u as f64),
            Value::Number(Number::I(i)) => Some(*i as f64),
            Value::Number(Number::F(f)) => Some(*f),
            _ => None,
        }
    }
    /// The number, if written as a non-negative integer.
    pub fn as_u64(&self) -> Option<u64> {
        match self {
            Value::Number(Number::U(u)) => Some(*u),
            _ => None,
        }
    }
    /// Is it a number?
    pub fn is_number(&self) -> bool {
        matches!(self, Value::Number(_))
    }

    fn write(&self, out: &mut String, budget: usize) {
        use std::fmt::Write;
        if out.len() > budget {
            return;
        }
        match self {
            Value::Null => out.push_str("null"),
            Value::Bool(b) => {
                let _ = write!(out, "{b}");
            }
            Value::Number(Number::U(u)) => {
                let _ = write!(out, "{u}");
            }
            Value::Number(Number::I(i)) => {
                let _ = write!(out, "{i}");
            }
            Value::Number(Number::F(f)) => {
                let _ = write!(out, "{f}");
            }
            Value::String(s) => {
                let _ = write!(out, "{:?}", &s[..s.floor_char_boundary_compat(budget)]);
            }
            Value::Array(a) => {
                out.push('[');
                for (i, v) in a.iter().enumerate() {
                    if i > 0 {
                        out.push(',');
                    }
                    v.write(out, budget);
                    if out.len() > budget {
                        return;
                    }
                }
                out.push(']');
            }
            Value::Object(m) => {
                out.push('{');
                for (i, (k, v)) in m.0.iter().enumerate() {
                    if i > 0 {
                        out.push(',');
                    }
                    let _ = write!(out, "{:?}:", &k[..k.floor_char_boundary_compat(budget)]);
                    v.write(out, budget);
                    if out.len() > budget {
                        return;
                    }
                }
                out.push('}');
            }
        }
    }
}

/// `str::floor_char_boundary` is not stable at the crate's MSRV.
trait FloorCharBoundary {
    fn floor_char_boundary_compat(&self, i: usize) -> usize;
}
impl FloorCharBoundary for str {
    fn floor_char_boundary_compat(&self, i: usize) -> usize {
        let mut i = i.min(self.len());
        while !self.is_char_boundary(i) {
            i -= 1;
        }
        i
    }
}

/// Compact JSON, cut at about 100 characters: error messages quote values, and
/// a hostile one may be megabytes long.
impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        const BUDGET: usize = 100;
        let mut s = String::new();
        self.write(&mut s, BUDGET);
        if s.len() > BUDGET {
            let cut = s.floor_char_boundary_compat(BUDGET);
            s.truncate(cut);
            s.push_str("...");
        }
        f.write_str(&s)
    }
}

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Value, D::Error> {
        d.deserialize_any(ValueVisitor)
    }
}

struct ValueVisitor;

impl<'de> Visitor<'de> for ValueVisitor {
    type Value = Value;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("any JSON value")
    }
    fn visit_bool<E>(self, b: bool) -> Result<Value, E> {
        Ok(Value::Bool(b))
    }
    fn visit_u64<E>(self, u: u64) -> Result<Value, E> {
        Ok(Value::Number(Number::U(u)))
    }
    fn visit_i64<E>(self, i: i64) -> Result<Value, E> {
        Ok(Value::Number(if i >= 0 { Number::U(i as u64) } else { Number::I(i) }))
    }
    fn visit_f64<E>(self, f: f64) -> Result<Value, E> {
        Ok(Value::Number(Number::F(f)))
    }
    fn visit_str<E>(self, s: &str) -> Result<Value, E> {
        Ok(Value::String(s.into()))
    }
    fn visit_string<E>(self, s: String) -> Result<Value, E> {
        Ok(Value::String(s.into_boxed_str()))
    }
    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }
    fn visit_none<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut v = Vec::new();
        while let Some(x) = seq.next_element()? {
            v.push(x);
        }
        Ok(Value::Array(v.into_boxed_slice()))
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut v: Vec<(Box<str>, Value)> = Vec::new();
        while let Some(k) = map.next_key::<String>()? {
            let x = map.next_value()?;
            v.push((k.into_boxed_str(), x));
        }
        Ok(Value::Object(Map(v.into_boxed_slice())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_like_serde_json_and_stays_small() {
        let v: Value = serde_json::from_str(r#"{"a":[1,-2,3.5,"x",null,true],"b":{"c":1},"a":7}"#).unwrap();
        let m = v.as_object().unwrap();
        assert_eq!(m["a"].as_u64(), Some(7), "a repeated key keeps its last value");
        assert_eq!(m["b"].as_object().unwrap()["c"].as_f64(), Some(1.0));
        assert_eq!(m["missing"], Value::Null);
        assert_eq!(std::mem::size_of::<Value>(), 24);
        let long = Value::Array(vec![Value::Number(Number::U(123456)); 100_000].into_boxed_slice());
        assert!(long.to_string().len() < 110, "{}", long.to_string().len());
    }
}

//! Numbers in a record. A finite number is written as a JSON number; the three non-finite values
//! — which JSON cannot hold and which `serde_json` would otherwise write as `null`, a value no
//! reader can tell apart or read back as a number — are written as the strings `"NaN"`, `"inf"`
//! and `"-inf"`. Reading accepts exactly these forms and rejects `null` with a message, so a
//! record written by this tool is always readable by it and never silently loses a value.
//!
//! Used field by field through `#[serde(with = "…")]` (modules [`scalar`], [`opt_scalar`],
//! [`vec`](mod@vec), `opt_vec`, `vec_vec`, [`array`](mod@array)) on every `f64` of every record type (run
//! records with their residuals, checks and intervals, reference records); the property test
//! `record_numbers.rs` writes non-finite values into each of them and reads them back.

use std::fmt;

use serde::de::{self, Deserializer, Visitor};
use serde::ser::Serializer;
use serde::{Deserialize, Serialize};

/// One record number, finite or not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl Serialize for Num {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let x = self.0;
        if x.is_finite() {
            s.serialize_f64(x)
        } else if x.is_nan() {
            s.serialize_str("NaN")
        } else if x > 0.0 {
            s.serialize_str("inf")
        } else {
            s.serialize_str("-inf")
        }
    }
}

struct NumVisitor;

impl Visitor<'_> for NumVisitor {
    type Value = Num;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number, or one of the strings \"NaN\", \"inf\", \"-inf\"")
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Num, E> {
        Ok(Num(v))
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Num, E> {
        Ok(Num(v as f64))
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Num, E> {
        Ok(Num(v as f64))
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<Num, E> {
        match v {
            "NaN" => Ok(Num(f64::NAN)),
            "inf" => Ok(Num(f64::INFINITY)),
            "-inf" => Ok(Num(f64::NEG_INFINITY)),
            other => Err(E::invalid_value(de::Unexpected::Str(other), &self)),
        }
    }
    fn visit_unit<E: de::Error>(self) -> Result<Num, E> {
        Err(E::custom(
            "null where a number belongs (records of schema 1 wrote a non-finite number as null; \
             which value it was is lost — compute the run again)",
        ))
    }
    fn visit_none<E: de::Error>(self) -> Result<Num, E> {
        self.visit_unit()
    }
}

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NumVisitor)
    }
}

/// `f64` fields.
pub mod scalar {
    use super::*;

    pub fn serialize<S: Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
        Num(*x).serialize(s)
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Num::deserialize(d).map(|n| n.0)
    }
}

/// `Option<f64>` fields (`null` is the absent value, never a number).
pub mod opt_scalar {
    use super::*;

    pub fn serialize<S: Serializer>(x: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        x.map(Num).serialize(s)
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        Ok(Option::<Num>::deserialize(d)?.map(|n| n.0))
    }
}

/// `[f64; N]` fields; another length is refused.
pub mod array {
    use super::*;

    pub fn serialize<S: Serializer, const N: usize>(x: &[f64; N], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(x.iter().map(|v| Num(*v)))
    }
    pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
        d: D,
    ) -> Result<[f64; N], D::Error> {
        let v = Vec::<Num>::deserialize(d)?;
        let len = v.len();
        let v: Vec<f64> = v.into_iter().map(|n| n.0).collect();
        v.try_into()
            .map_err(|_| de::Error::invalid_length(len, &format!("{N} numbers").as_str()))
    }
}

/// `Vec<f64>` fields.
pub mod vec {
    use super::*;

    pub fn serialize<S: Serializer>(x: &[f64], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(x.iter().map(|v| Num(*v)))
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        Ok(Vec::<Num>::deserialize(d)?
            .into_iter()
            .map(|n| n.0)
            .collect())
    }
}

/// `Option<Vec<f64>>` fields.
pub(crate) mod opt_vec {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(x: &Option<Vec<f64>>, s: S) -> Result<S::Ok, S::Error> {
        x.as_ref()
            .map(|v| v.iter().map(|v| Num(*v)).collect::<Vec<_>>())
            .serialize(s)
    }
    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<Vec<f64>>, D::Error> {
        Ok(Option::<Vec<Num>>::deserialize(d)?.map(|v| v.into_iter().map(|n| n.0).collect()))
    }
}

/// `Vec<Vec<f64>>` fields.
pub(crate) mod vec_vec {
    use super::*;

    pub(crate) fn serialize<S: Serializer>(x: &[Vec<f64>], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(
            x.iter()
                .map(|row| row.iter().map(|v| Num(*v)).collect::<Vec<_>>()),
        )
    }
    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<f64>>, D::Error> {
        Ok(Vec::<Vec<Num>>::deserialize(d)?
            .into_iter()
            .map(|row| row.into_iter().map(|n| n.0).collect())
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Serialize, Deserialize)]
    struct R {
        #[serde(with = "super::scalar")]
        a: f64,
        #[serde(with = "super::vec")]
        b: Vec<f64>,
        #[serde(with = "super::opt_vec")]
        c: Option<Vec<f64>>,
        #[serde(with = "super::vec_vec")]
        d: Vec<Vec<f64>>,
    }

    #[test]
    fn non_finite_numbers_round_trip_as_named_strings() {
        let r = R {
            a: f64::INFINITY,
            b: vec![1.5, f64::NAN, f64::NEG_INFINITY, 3.0],
            c: Some(vec![f64::INFINITY, 0.0]),
            d: vec![vec![f64::NAN], vec![2.0]],
        };
        let text = serde_json::to_string(&r).unwrap();
        assert_eq!(
            text,
            r#"{"a":"inf","b":[1.5,"NaN","-inf",3.0],"c":["inf",0.0],"d":[["NaN"],[2.0]]}"#
        );
        let back: R = serde_json::from_str(&text).unwrap();
        assert_eq!(back.a, f64::INFINITY);
        assert!(back.b[1].is_nan() && back.b[2] == f64::NEG_INFINITY && back.b[3] == 3.0);
        assert_eq!(back.c.unwrap()[0], f64::INFINITY);
        assert!(back.d[0][0].is_nan());
    }

    #[test]
    fn null_and_other_strings_are_refused_with_a_reason() {
        let e = serde_json::from_str::<R>(r#"{"a":null,"b":[],"c":null,"d":[]}"#).unwrap_err();
        assert!(e.to_string().contains("null where a number belongs"), "{e}");
        let e =
            serde_json::from_str::<R>(r#"{"a":"Infinity","b":[],"c":null,"d":[]}"#).unwrap_err();
        assert!(e.to_string().contains("\"Infinity\""), "{e}");
        let ok: R = serde_json::from_str(r#"{"a":3,"b":[-1],"c":null,"d":[]}"#).unwrap();
        assert_eq!((ok.a, ok.b[0]), (3.0, -1.0));
    }
}

//! `serde::Deserializer` for [`Ast`]: params structs are read from the spanned tree, and every
//! error carries the span of the value (or field name) it is about.

use std::fmt;

use serde::de::{
    self, DeserializeOwned, DeserializeSeed, EnumAccess, IntoDeserializer, MapAccess, SeqAccess,
    VariantAccess, Visitor,
};
use serde::forward_to_deserialize_any;

use super::{Ast, Name, Span, Value, did_you_mean};

/// A deserialization error, with the span of the value it is about when known.
#[derive(Clone, Debug, PartialEq)]
pub struct DeError {
    /// What was expected and found.
    pub message: String,
    /// Where.
    pub span: Option<Span>,
}

impl DeError {
    fn at(mut self, span: Span) -> Self {
        self.span.get_or_insert(span);
        self
    }
}

impl fmt::Display for DeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for DeError {}

fn suggest(word: &str, expected: &'static [&'static str], what: &str) -> String {
    match did_you_mean(word, expected.iter().copied()) {
        Some(m) => format!("unknown {what} `{word}`; did you mean `{m}`?"),
        None if expected.is_empty() => format!("unknown {what} `{word}`; there are none"),
        None => format!(
            "unknown {what} `{word}`; expected one of: {}",
            expected.join(", ")
        ),
    }
}

impl de::Error for DeError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        DeError {
            message: msg.to_string(),
            span: None,
        }
    }
    fn unknown_field(field: &str, expected: &'static [&'static str]) -> Self {
        Self::custom(suggest(field, expected, "field"))
    }
    fn unknown_variant(variant: &str, expected: &'static [&'static str]) -> Self {
        Self::custom(suggest(variant, expected, "variant"))
    }
    fn invalid_type(unexp: de::Unexpected, exp: &dyn de::Expected) -> Self {
        Self::custom(format!("expected {exp}, found {unexp}"))
    }
    fn invalid_value(unexp: de::Unexpected, exp: &dyn de::Expected) -> Self {
        Self::custom(format!("expected {exp}, found {unexp}"))
    }
    fn missing_field(field: &'static str) -> Self {
        Self::custom(format!("missing field `{field}`"))
    }
}

/// Deserializes a `T` from `ast`.
pub fn from_ast<T: DeserializeOwned>(ast: &Ast) -> Result<T, DeError> {
    T::deserialize(ast)
}

fn invalid(ast: &Ast, expected: &str) -> DeError {
    DeError {
        message: format!("expected {expected}, found {}", ast.v.describe()),
        span: Some(ast.span),
    }
}

impl<'de> de::Deserializer<'de> for &Ast {
    type Error = DeError;

    fn deserialize_any<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        let r = match &self.v {
            Value::Bool(b) => v.visit_bool(*b),
            Value::Int(i) => match i64::try_from(*i) {
                Ok(i) => v.visit_i64(i),
                Err(_) => match u64::try_from(*i) {
                    Ok(u) => v.visit_u64(u),
                    Err(_) => v.visit_i128(*i),
                },
            },
            Value::Float(f) => v.visit_f64(*f),
            Value::Str(s) => v.visit_str(s),
            Value::Char(c) => v.visit_char(*c),
            Value::Unit => v.visit_unit(),
            Value::Ident(s) if s == "None" => v.visit_none(),
            Value::Ident(s) => v.visit_str(s),
            Value::List(items) | Value::Tuple(items) => v.visit_seq(Seq(items.iter())),
            Value::Map(entries) => v.visit_map(map_pairs(entries)),
            Value::Struct { fields, .. } => v.visit_map(struct_pairs(fields)),
            Value::Call { name, args } if name.name == "Some" && args.len() == 1 => {
                v.visit_some(&args[0])
            }
            Value::Call { args, .. } => v.visit_seq(Seq(args.iter())),
        };
        r.map_err(|e| e.at(self.span))
    }

    fn deserialize_f64<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        match &self.v {
            // Integers are fine where a float is expected: `cell_m: 1` means 1.0.
            Value::Int(i) => v.visit_f64(*i as f64).map_err(|e: DeError| e.at(self.span)),
            Value::Float(f) => v.visit_f64(*f).map_err(|e: DeError| e.at(self.span)),
            _ => Err(invalid(self, "a number")),
        }
    }
    fn deserialize_f32<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        self.deserialize_f64(v)
    }

    fn deserialize_option<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        let r = match &self.v {
            Value::Ident(s) if s == "None" => v.visit_none(),
            Value::Call { name, args } if name.name == "Some" && args.len() == 1 => {
                v.visit_some(&args[0])
            }
            // A bare value where an option is expected means Some(value).
            _ => v.visit_some(self),
        };
        r.map_err(|e| e.at(self.span))
    }

    fn deserialize_unit<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        match &self.v {
            Value::Unit => v.visit_unit(),
            Value::Tuple(t) | Value::List(t) if t.is_empty() => v.visit_unit(),
            _ => Err(invalid(self, "`()`")),
        }
    }
    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        v: V,
    ) -> Result<V::Value, DeError> {
        self.deserialize_unit(v)
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        v: V,
    ) -> Result<V::Value, DeError> {
        match &self.v {
            Value::Call { name: n, args } if n.name == name && args.len() == 1 => {
                v.visit_newtype_struct(&args[0])
            }
            _ => v.visit_newtype_struct(self),
        }
        .map_err(|e| e.at(self.span))
    }

    fn deserialize_seq<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        match &self.v {
            Value::List(items) | Value::Tuple(items) => {
                v.visit_seq(Seq(items.iter())).map_err(|e| e.at(self.span))
            }
            _ => Err(invalid(self, "a list")),
        }
    }
    fn deserialize_tuple<V: Visitor<'de>>(self, len: usize, v: V) -> Result<V::Value, DeError> {
        match &self.v {
            Value::List(items) | Value::Tuple(items) if items.len() == len => {
                v.visit_seq(Seq(items.iter())).map_err(|e| e.at(self.span))
            }
            _ => Err(invalid(self, &format!("a tuple of {len}"))),
        }
    }
    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        len: usize,
        v: V,
    ) -> Result<V::Value, DeError> {
        match &self.v {
            Value::Call { name: n, args } if n.name == name && args.len() == len => {
                v.visit_seq(Seq(args.iter())).map_err(|e| e.at(self.span))
            }
            _ => self.deserialize_tuple(len, v),
        }
    }

    fn deserialize_map<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        match &self.v {
            Value::Map(entries) => v.visit_map(map_pairs(entries)),
            Value::Struct { name: None, fields } => v.visit_map(struct_pairs(fields)),
            _ => return Err(invalid(self, "a map `{key: value, ...}`")),
        }
        .map_err(|e| e.at(self.span))
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        known: &'static [&'static str],
        v: V,
    ) -> Result<V::Value, DeError> {
        match &self.v {
            Value::Struct { name: Some(n), .. } if n.name != name => Err(DeError {
                message: format!("expected `{name}(...)`, found `{}(...)`", n.name),
                span: Some(n.span),
            }),
            Value::Struct { fields, .. } => {
                only_known_fields(fields, known)?;
                v.visit_map(struct_pairs(fields))
                    .map_err(|e| e.at(self.span))
            }
            Value::Unit => v.visit_map(struct_pairs(&[])).map_err(|e| e.at(self.span)),
            _ => Err(invalid(self, &format!("`{name}(field: value, ...)`"))),
        }
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        v: V,
    ) -> Result<V::Value, DeError> {
        match &self.v {
            Value::Ident(s) | Value::Str(s) => v.visit_enum(Variant {
                name: Name {
                    name: s.clone(),
                    span: self.span,
                },
                body: None,
            }),
            Value::Call { name, .. }
            | Value::Struct {
                name: Some(name), ..
            } => v.visit_enum(Variant {
                name: name.clone(),
                body: Some(self),
            }),
            _ => return Err(invalid(self, "an enum variant")),
        }
        .map_err(|e| e.at(self.span))
    }

    fn deserialize_identifier<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        match &self.v {
            Value::Ident(s) | Value::Str(s) => v.visit_str(s).map_err(|e: DeError| e.at(self.span)),
            _ => Err(invalid(self, "an identifier")),
        }
    }

    fn deserialize_ignored_any<V: Visitor<'de>>(self, v: V) -> Result<V::Value, DeError> {
        v.visit_unit()
    }

    forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 char str string bytes byte_buf
    }
}

struct Seq<'a>(std::slice::Iter<'a, Ast>);

impl<'de, 'a> SeqAccess<'de> for Seq<'a> {
    type Error = DeError;
    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, DeError> {
        self.0.next().map(|a| seed.deserialize(a)).transpose()
    }
    fn size_hint(&self) -> Option<usize> {
        Some(self.0.len())
    }
}

/// A map key: a value (`{k: v}` maps) or a field name (structs).
#[derive(Clone, Copy)]
enum Key<'a> {
    Value(&'a Ast),
    Field(&'a Name),
}

/// Every field of a struct value must be one its type declares. serde's derive skips unknown
/// fields unless a type says `deny_unknown_fields`, so a typo inside a nested struct
/// (`antenna: (downtilt: 10.0)`) or a `--set` into one would load and change nothing: checked
/// here for every struct and struct variant, whatever its type says.
fn only_known_fields(
    fields: &[(Name, Ast)],
    known: &'static [&'static str],
) -> Result<(), DeError> {
    match fields
        .iter()
        .find(|(k, _)| !known.contains(&k.name.as_str()))
    {
        Some((k, _)) => Err(DeError {
            message: suggest(&k.name, known, "field"),
            span: Some(k.span),
        }),
        None => Ok(()),
    }
}

/// Entries of a map or fields of a struct, as serde map access.
struct Pairs<'a, I: Iterator<Item = (Key<'a>, &'a Ast)>> {
    it: I,
    value: Option<&'a Ast>,
}

fn map_pairs(e: &[(Ast, Ast)]) -> Pairs<'_, impl Iterator<Item = (Key<'_>, &Ast)>> {
    Pairs {
        it: e.iter().map(|(k, v)| (Key::Value(k), v)),
        value: None,
    }
}

fn struct_pairs(f: &[(Name, Ast)]) -> Pairs<'_, impl Iterator<Item = (Key<'_>, &Ast)>> {
    Pairs {
        it: f.iter().map(|(k, v)| (Key::Field(k), v)),
        value: None,
    }
}

impl<'de, 'a, I: Iterator<Item = (Key<'a>, &'a Ast)>> MapAccess<'de> for Pairs<'a, I> {
    type Error = DeError;
    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, DeError> {
        let Some((k, v)) = self.it.next() else {
            return Ok(None);
        };
        self.value = Some(v);
        match k {
            Key::Value(k) => seed.deserialize(k).map(Some),
            Key::Field(k) => {
                let key: de::value::StrDeserializer<'_, DeError> =
                    k.name.as_str().into_deserializer();
                seed.deserialize(key).map(Some).map_err(|e| e.at(k.span))
            }
        }
    }
    fn next_value_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<T::Value, DeError> {
        seed.deserialize(self.value.take().expect("next_key before next_value"))
    }
}

struct Variant<'a> {
    name: Name,
    body: Option<&'a Ast>,
}

impl<'de, 'a> EnumAccess<'de> for Variant<'a> {
    type Error = DeError;
    type Variant = Self;
    fn variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<(T::Value, Self), DeError> {
        let key: de::value::StrDeserializer<'_, DeError> =
            self.name.name.as_str().into_deserializer();
        let v = seed.deserialize(key).map_err(|e| e.at(self.name.span))?;
        Ok((v, self))
    }
}

impl<'de, 'a> VariantAccess<'de> for Variant<'a> {
    type Error = DeError;
    fn unit_variant(self) -> Result<(), DeError> {
        match self.body {
            None => Ok(()),
            Some(b) => Err(invalid(
                b,
                &format!("the bare variant `{}`", self.name.name),
            )),
        }
    }
    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, DeError> {
        match self.body.map(|b| (b, &b.v)) {
            Some((_, Value::Call { args, .. })) if args.len() == 1 => seed.deserialize(&args[0]),
            Some((b, _)) => Err(invalid(b, &format!("`{}(value)`", self.name.name))),
            None => Err(DeError {
                message: format!("expected `{}(value)`", self.name.name),
                span: Some(self.name.span),
            }),
        }
    }
    fn tuple_variant<V: Visitor<'de>>(self, len: usize, v: V) -> Result<V::Value, DeError> {
        match self.body.map(|b| (b, &b.v)) {
            Some((_, Value::Call { args, .. })) if args.len() == len => {
                v.visit_seq(Seq(args.iter()))
            }
            Some((b, _)) => Err(invalid(
                b,
                &format!("`{}(...)` with {len} values", self.name.name),
            )),
            None => Err(DeError {
                message: format!("expected `{}(...)`", self.name.name),
                span: Some(self.name.span),
            }),
        }
    }
    fn struct_variant<V: Visitor<'de>>(
        self,
        known: &'static [&'static str],
        v: V,
    ) -> Result<V::Value, DeError> {
        match self.body.map(|b| (b, &b.v)) {
            Some((_, Value::Struct { fields, .. })) => {
                only_known_fields(fields, known)?;
                v.visit_map(struct_pairs(fields))
            }
            Some((b, _)) => Err(invalid(
                b,
                &format!("`{}(field: value, ...)`", self.name.name),
            )),
            None => Err(DeError {
                message: format!("expected `{}(field: value, ...)`", self.name.name),
                span: Some(self.name.span),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::syntax::parse;
    use serde::Deserialize;
    use std::collections::BTreeMap;

    #[derive(Debug, Deserialize, PartialEq)]
    enum Mode {
        Max,
        Min,
        Pct(f64),
    }

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct P {
        sigma_m: f64,
        mode: Mode,
        #[serde(default)]
        cap: Option<u32>,
        #[serde(default)]
        weights: BTreeMap<String, f64>,
        size: (f64, f64),
    }

    fn de(s: &str) -> Result<P, DeError> {
        from_ast(&parse(s, 0, 1, 1).unwrap())
    }

    #[test]
    fn reads_structs_enums_options_maps() {
        let p =
            de("P(sigma_m: 2, mode: Pct(5.0), cap: 3, weights: {\"glass\": 1.2}, size: (1, 2.5))")
                .unwrap();
        assert_eq!(p.sigma_m, 2.0);
        assert_eq!(p.mode, Mode::Pct(5.0));
        assert_eq!(p.cap, Some(3));
        assert_eq!(p.weights["glass"], 1.2);
        assert_eq!(p.size, (1.0, 2.5));
        let p = de("(sigma_m: 1.0, mode: Min, cap: None, size: (0, 0))").unwrap();
        assert_eq!((p.mode, p.cap), (Mode::Min, None));
        assert_eq!(
            de("(sigma_m: 1.0, mode: Max, cap: Some(4), size: (0, 0))")
                .unwrap()
                .cap,
            Some(4)
        );
    }

    /// A type without `deny_unknown_fields`, nested in one with it, and as an enum's struct
    /// variant: an unknown field in either is an error, where serde alone would skip it.
    #[derive(Debug, Deserialize, PartialEq)]
    struct Loose {
        tilt: f64,
    }

    #[derive(Debug, Deserialize, PartialEq)]
    enum Layout {
        Cells { path: String },
    }

    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Outer {
        inner: Loose,
        layout: Layout,
    }

    #[test]
    fn unknown_fields_of_nested_structs_and_variants_are_errors() {
        let de = |s: &str| from_ast::<Outer>(&parse(s, 0, 1, 1).unwrap());
        let ok = de("(inner: (tilt: 1.0), layout: Cells(path: \"a\"))").unwrap();
        assert_eq!(ok.inner.tilt, 1.0);
        let e = de("(inner: (tilt: 1.0, tlt: 2.0), layout: Cells(path: \"a\"))").unwrap_err();
        assert_eq!(e.message, "unknown field `tlt`; did you mean `tilt`?");
        assert_eq!(e.span.map(|s| s.col), Some(21));
        let e = de("(inner: (tilt: 1.0), layout: Cells(path: \"a\", cells: 3))").unwrap_err();
        assert!(
            e.message.starts_with("unknown field `cells`"),
            "{}",
            e.message
        );
    }

    #[test]
    fn errors_point_at_the_value() {
        let e = de("(sigma_m: 1.0,\n mode: Mx, size: (0, 0))").unwrap_err();
        assert_eq!(e.message, "unknown variant `Mx`; did you mean `Max`?");
        assert_eq!(e.span.map(|s| (s.line, s.col)), Some((2, 8)));
        let e = de("(sigma_m: 1.0, mode: Max, sigma: 2, size: (0, 0))").unwrap_err();
        assert_eq!(e.message, "unknown field `sigma`; did you mean `sigma_m`?");
        assert_eq!(e.span.map(|s| s.col), Some(27));
        let e = de("(sigma_m: \"x\", mode: Max, size: (0, 0))").unwrap_err();
        assert_eq!(e.message, "expected a number, found string \"x\"");
        assert_eq!(e.span.map(|s| s.col), Some(11));
        let e = de("(sigma_m: 1, mode: Max, cap: -1, size: (0, 0))").unwrap_err();
        assert_eq!(e.message, "expected u32, found integer `-1`");
        assert_eq!(e.span.map(|s| s.col), Some(30));
        let e = de("(mode: Max, size: (0, 0))").unwrap_err();
        assert_eq!(e.message, "missing field `sigma_m`");
        assert_eq!(e.span.map(|s| s.col), Some(1));
    }
}

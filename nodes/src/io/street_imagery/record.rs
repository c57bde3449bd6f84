//! The JSON of provider files: one record (an entity, a STAC item) read field by field with errors
//! that name the file, the record and the field, record ids, and a parser that lets the bare
//! `NaN` and `Infinity` tokens some writers emit reach the field that holds them.

use std::path::Path;

use serde_json::Value;

use crate::stage::StageError;

/// A GeoJSON Point: [lon, lat] (degrees) and the height when given.
pub type LonLatAlt = ([f64; 2], Option<f64>);

/// One record of a provider file (an entity, a STAC item): reads its fields with errors that name
/// the file, the record and the field.
pub struct Record<'a> {
    /// The file.
    pub file: &'a Path,
    /// The record in it, e.g. `image 1234` or `line 7 (image 1234)`.
    pub at: String,
    /// Its JSON.
    pub v: &'a Value,
}

impl Record<'_> {
    /// A `BadInput` on `field`.
    pub fn bad(&self, field: &str, expected: impl Into<String>) -> StageError {
        StageError::bad_input(
            self.file,
            format!("{}, `{field}`", self.at),
            format!("expected {}", expected.into()),
        )
    }

    /// The value at a dotted path (`properties.view:azimuth`); null counts as absent.
    pub fn get(&self, path: &str) -> Option<&Value> {
        path.split('.')
            .try_fold(self.v, |v, k| v.get(k))
            .filter(|v| !v.is_null())
    }

    /// A finite number, if present.
    pub fn num(&self, path: &str) -> Result<Option<f64>, StageError> {
        self.get(path)
            .map(|v| finite(v).ok_or_else(|| self.bad(path, format!("a finite number, found {v}"))))
            .transpose()
    }

    /// A string, if present.
    pub fn str(&self, path: &str) -> Result<Option<&str>, StageError> {
        self.get(path)
            .map(|v| {
                v.as_str()
                    .ok_or_else(|| self.bad(path, format!("a string, found {v}")))
            })
            .transpose()
    }

    /// `n` finite numbers, if present.
    pub fn nums(
        &self,
        path: &str,
        n: std::ops::RangeInclusive<usize>,
    ) -> Result<Option<Vec<f64>>, StageError> {
        let Some(v) = self.get(path) else {
            return Ok(None);
        };
        let want = || {
            format!(
                "an array of {} to {} finite numbers, found {v}",
                n.start(),
                n.end()
            )
        };
        let a = v
            .as_array()
            .filter(|a| n.contains(&a.len()))
            .ok_or_else(|| self.bad(path, want()))?;
        a.iter()
            .map(|x| finite(x).ok_or_else(|| self.bad(path, want())))
            .collect::<Result<Vec<f64>, _>>()
            .map(Some)
    }

    /// A GeoJSON Point's [lon, lat] (degrees) and altitude, if present.
    pub fn point(&self, path: &str) -> Result<Option<LonLatAlt>, StageError> {
        let Some(g) = self.get(path) else {
            return Ok(None);
        };
        let expected = "a GeoJSON Point {\"type\": \"Point\", \"coordinates\": [lon, lat]}";
        if g.get("type").and_then(Value::as_str) != Some("Point") {
            return Err(self.bad(path, expected));
        }
        let c = self
            .nums(&format!("{path}.coordinates"), 2..=3)?
            .ok_or_else(|| self.bad(path, expected))?;
        if !(c[0].abs() <= 180.0 && c[1].abs() < 89.9) {
            return Err(self.bad(
                path,
                format!(
                    "a longitude within ±180 and a latitude within ±89.9 degrees, found [{}, {}]",
                    c[0], c[1]
                ),
            ));
        }
        Ok(Some(([c[0], c[1]], c.get(2).copied())))
    }

    /// A pixel count in 1..=100000, required.
    pub fn pixels(&self, path: &str) -> Result<u32, StageError> {
        let n = self.num(path)?;
        match n {
            Some(n) if (1.0..=100_000.0).contains(&n) && n.fract() == 0.0 => Ok(n as u32),
            _ => Err(self.bad(path, "a whole number of pixels, 1 to 100000")),
        }
    }
}

fn finite(v: &Value) -> Option<f64> {
    v.as_f64().filter(|x| x.is_finite())
}

/// A record id made safe for file names: ASCII letters, digits, `-`, `_`, `.`, not leading `.`.
pub fn record_id(rec: &Record, path: &str) -> Result<String, StageError> {
    let id = match rec.get(path) {
        Some(Value::String(s)) => s.clone(),
        Some(Value::Number(n)) if n.is_u64() => n.to_string(),
        _ => return Err(rec.bad(path, "an id (a string or a whole number)")),
    };
    let ok = !id.is_empty()
        && id.len() <= 128
        && !id.starts_with('.')
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    if ok {
        Ok(id)
    } else {
        Err(rec.bad(
            path,
            format!("an id of letters, digits, '-', '_' and '.', found {id:?}"),
        ))
    }
}

/// Parses JSON; the bare tokens `NaN`, `Infinity` and `-Infinity` that some writers emit are read
/// as strings, so that the field holding one is named by the reader of that field.
pub fn parse_json(file: &Path, text: &str, place: &str) -> Result<Value, StageError> {
    let mut quoted = String::with_capacity(text.len());
    let (mut in_str, mut escaped) = (false, false);
    let mut rest = text;
    while let Some(c) = rest.chars().next() {
        if !in_str {
            if let Some(tok) = ["NaN", "Infinity", "-Infinity"]
                .into_iter()
                .find(|t| rest.starts_with(t))
            {
                quoted.push('"');
                quoted.push_str(tok);
                quoted.push('"');
                rest = &rest[tok.len()..];
                continue;
            }
            in_str = c == '"';
        } else if escaped {
            escaped = false;
        } else if c == '\\' {
            escaped = true;
        } else if c == '"' {
            in_str = false;
        }
        quoted.push(c);
        rest = &rest[c.len_utf8()..];
    }
    serde_json::from_str(&quoted).map_err(|e| {
        StageError::bad_input(
            file,
            format!("{place}line {}, column {}", e.line(), e.column()),
            format!("expected JSON: {e}"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nonfinite_tokens_become_strings() {
        let v = parse_json(
            Path::new("x"),
            r#"{"a": NaN, "b": "NaN \" Infinity", "c": [-Infinity, 1]}"#,
            "",
        )
        .unwrap();
        assert_eq!(v["a"], "NaN");
        assert_eq!(v["b"], "NaN \" Infinity");
        assert_eq!(v["c"][0], "-Infinity");
    }
}

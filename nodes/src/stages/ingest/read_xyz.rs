//! Ingest of ASCII XYZ point files (PDAL's text writer, CloudCompare, LAStools' las2txt).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::artifact::{PodVec, PointSet};
use crate::stage::{Ctx, FileRef, InputSpec, Inputs, Stage, StageError};

/// Params of [`ReadXyz`].
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadXyzParams {
    /// The file: one point per line, `x y z [class]`, separated by spaces, tabs or commas, in the
    /// site CRS (absolute coordinates). One header line and `#` comments are allowed.
    pub path: String,
}

/// Reads an ASCII XYZ point file into the site frame.
pub struct ReadXyz;

impl Stage for ReadXyz {
    const KIND: &'static str = "ReadXyz";
    const VERSION: u32 = 1;
    const DOC: &'static str = "ASCII XYZ points (x y z [class], site CRS) into the site frame";
    const INPUTS: &'static [InputSpec] = &[];
    type Params = ReadXyzParams;
    type Output = PointSet;

    fn files(p: &Self::Params) -> Vec<FileRef> {
        vec![FileRef {
            field: "path",
            path: p.path.clone(),
        }]
    }

    fn run(_: &Self::Params, _: &Inputs, ctx: &Ctx) -> Result<PointSet, StageError> {
        let path = ctx.file(0)?;
        let text = crate::io::open::read_regular(path)
            .map_err(|e| StageError::bad_input(path, "open", e.to_string()))?;
        let text = std::str::from_utf8(&text).map_err(|e| {
            StageError::bad_input(
                path,
                format!("byte {}", e.valid_up_to()),
                "expected UTF-8 text",
            )
        })?;
        parse_xyz(path, text, ctx.site.origin)
    }
}

/// Parses XYZ text; coordinates are shifted by `origin` into the site frame.
pub fn parse_xyz(path: &Path, text: &str, origin: (f64, f64)) -> Result<PointSet, StageError> {
    let mut xyz = Vec::new();
    let mut class = Vec::new();
    let mut saw_class = None;
    // Only the first line that is not a comment may be a header: a file of text is an error on
    // its second line, not an empty point set.
    let mut header_seen = false;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let fields: Vec<(usize, &str)> = split_fields(line);
        let first_is_number = fields
            .first()
            .is_some_and(|(_, f)| f.parse::<f64>().is_ok());
        if !header_seen && xyz.is_empty() && !first_is_number {
            header_seen = true;
            continue;
        }
        header_seen = true;
        if fields.len() < 3 || fields.len() > 4 {
            return Err(StageError::bad_input(
                path,
                format!("line {line_no}"),
                format!(
                    "expected 3 or 4 fields (x y z [class]), found {}",
                    fields.len()
                ),
            ));
        }
        let mut v = [0f64; 3];
        for k in 0..3 {
            let (col, f) = fields[k];
            v[k] = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    StageError::bad_input(
                        path,
                        format!("line {line_no}, column {}", col + 1),
                        format!("expected a number, found {f:?}"),
                    )
                })?;
        }
        let has_class = fields.len() == 4;
        if *saw_class.get_or_insert(has_class) != has_class {
            return Err(StageError::bad_input(
                path,
                format!("line {line_no}"),
                "expected the same number of fields on every line",
            ));
        }
        if has_class {
            let (col, f) = fields[3];
            let c = f
                .parse::<f64>()
                .ok()
                .filter(|c| c.fract() == 0.0 && (0.0..=255.0).contains(c))
                .ok_or_else(|| {
                    StageError::bad_input(
                        path,
                        format!("line {line_no}, column {}", col + 1),
                        format!("expected a class 0-255, found {f:?}"),
                    )
                })?;
            class.push(c as u8);
        }
        let site = [v[0] - origin.0, v[1] - origin.1, v[2]];
        if let Some(k) = site
            .iter()
            .position(|c| !(c.abs() <= crate::artifact::MAX_COORD_M as f64))
        {
            return Err(StageError::bad_input(
                path,
                format!("line {line_no}, column {}", fields[k].0 + 1),
                format!(
                    "expected a coordinate within {:e} m of the site origin, found {}",
                    crate::artifact::MAX_COORD_M,
                    fields[k].1
                ),
            ));
        }
        xyz.push(site.map(|c| c as f32));
    }
    if xyz.is_empty() {
        return Err(StageError::bad_input(
            path,
            format!("line {}", text.lines().count().max(1)),
            "expected at least one point (x y z [class]); the file ended without any",
        ));
    }
    Ok(PointSet {
        xyz: PodVec(xyz),
        class: PodVec(class),
        ..Default::default()
    })
}

/// Fields and their 0-based character offsets.
fn split_fields(line: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, ch) in line.char_indices() {
        let sep = ch.is_whitespace() || ch == ',' || ch == ';';
        match (sep, start) {
            (true, Some(s)) => {
                out.push((s, &line[s..i]));
                start = None;
            }
            (false, None) => start = Some(i),
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, &line[s..]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_header_comments_and_classes() {
        let p = Path::new("t.xyz");
        let ps = parse_xyz(
            p,
            "x,y,z,class\n# c\n100.5, 200.25, 3, 2\n101 201 4 6\n",
            (100.0, 200.0),
        )
        .unwrap();
        assert_eq!(ps.xyz.0, vec![[0.5, 0.25, 3.0], [1.0, 1.0, 4.0]]);
        assert_eq!(ps.class.0, vec![2, 6]);
    }

    #[test]
    fn bad_number_names_line_and_column() {
        let e = parse_xyz(Path::new("t.xyz"), "1 2 3\n4 five 6\n", (0.0, 0.0)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.xyz: line 2, column 3: expected a number, found \"five\""
        );
    }
}

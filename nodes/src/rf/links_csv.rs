//! The link files of the `trace` command: `tx_x,tx_y,tx_z,rx_x,rx_y,rx_z` per row (other columns
//! ignored), and the same columns with the traced gains written back.

use std::path::Path;

use crate::stage::StageError;

use super::path::{LinkEnds, LinkPaths};

/// The (tx, rx) pairs of a links CSV.
pub fn read_links(path: &Path) -> Result<Vec<LinkEnds>, StageError> {
    let bad = |place: String, expected: &str| StageError::bad_input(path, place, expected);
    let mut r = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| bad("file".into(), &format!("a readable CSV file ({e})")))?;
    let headers = r
        .headers()
        .map_err(|e| bad("header".into(), &format!("a header row ({e})")))?
        .clone();
    let names = ["tx_x", "tx_y", "tx_z", "rx_x", "rx_y", "rx_z"];
    for n in names {
        let at: Vec<usize> = (0..headers.len()).filter(|&i| &headers[i] == n).collect();
        if at.len() > 1 {
            return Err(bad(
                "header".into(),
                &format!(
                    "each column once; {n} is columns {} and {}",
                    at[0] + 1,
                    at[1] + 1
                ),
            ));
        }
    }
    let cols: Vec<usize> = names
        .iter()
        .map(|n| {
            headers.iter().position(|h| h == *n).ok_or_else(|| {
                bad(
                    "header".into(),
                    &format!("a column {n} (columns tx_x,tx_y,tx_z,rx_x,rx_y,rx_z)"),
                )
            })
        })
        .collect::<Result<_, _>>()?;
    let mut out = Vec::new();
    for (i, rec) in r.records().enumerate() {
        let line = i + 2;
        let rec = rec.map_err(|e| bad(format!("line {line}"), &format!("a CSV record ({e})")))?;
        let mut v = [0.0; 6];
        for (k, &c) in cols.iter().enumerate() {
            let s = rec.get(c).unwrap_or("");
            v[k] = s
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    bad(
                        format!("line {line}, column {}", names[k]),
                        &format!("a number, not {s:?}"),
                    )
                })?;
        }
        for (end, p) in [("tx", [v[0], v[1], v[2]]), ("rx", [v[3], v[4], v[5]])] {
            crate::params::check_point(p).map_err(|m| bad(format!("line {line}, {end}"), &m))?;
        }
        out.push(([v[0], v[1], v[2]], [v[3], v[4], v[5]]));
    }
    Ok(out)
}

/// The links with their traced gains as CSV text.
pub fn write_results(links: &[LinkEnds], results: &[LinkPaths]) -> String {
    let mut s = String::from(
        "tx_x,tx_y,tx_z,rx_x,rx_y,rx_z,path_gain_db,coherent_path_gain_db,num_paths\n",
    );
    for ((tx, rx), r) in links.iter().zip(results) {
        s.push_str(&format!(
            "{},{},{},{},{},{},{:.4},{:.4},{}\n",
            tx[0],
            tx[1],
            tx[2],
            rx[0],
            rx[1],
            rx[2],
            r.gain_db,
            r.coherent_gain_db,
            r.paths.len()
        ));
    }
    s
}

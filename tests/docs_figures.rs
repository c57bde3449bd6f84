//! The README quotes only the page of current figures (BENCHMARKS.md), and that page says for
//! every figure how, where and when it was measured.
//!
//! The rule for the README: every figure in dB it states must appear on BENCHMARKS.md. A figure
//! in dB is
//! - a number, or numbers joined by `-`, `–` or ` / ` (a range, or all / LOS / NLOS), followed by
//!   ` dB` (not `dB/m` or `dBm`), anywhere in README.md: the demo's Table 1 paragraph, the status,
//!   the radio section, the real-data sections alike;
//! - every number in a README table row after a cell that says `(dB)` (Table 1's cells).
//!
//! Each of its numbers appears on BENCHMARKS.md when the same digits (`0.14` is not `0.138`)
//! stand as a number in a line of the page that says `dB`, or in a row of a table whose header
//! says `dB`. Signs are not compared: the page may give -145.6 where the README says 145.6 dB of
//! loss.
//!
//! The rule for BENCHMARKS.md: every `## ` section carries a date (YYYY-MM-DD) and a command (an
//! inline code span starting with `cargo `, `kodama-dag `, `scripts/`, `python3 `,
//! `/usr/bin/time ` or `FUZZ_SECONDS=`).
//!
//! Std only: the documents are read from CARGO_MANIFEST_DIR.

use std::collections::BTreeSet;
use std::path::Path;

/// A figure in dB the README states: where, what it says, the numbers in it.
#[derive(Debug, PartialEq)]
struct Figure {
    line: usize,
    text: String,
    numbers: Vec<String>,
}

fn is_num_char(c: char) -> bool {
    c.is_ascii_digit() || c == '.' || c == ','
}

/// The numbers in `s`: runs of digits, `.` and `,` that hold a digit, without a trailing `.` or
/// `,` (the end of a sentence or a list), and not part of a word (`rx23`, a commit `2c95b20`).
fn numbers(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut in_word = false;
    let mut prev = ' ';
    for c in s.chars().chain(std::iter::once(' ')) {
        if is_num_char(c) {
            if cur.is_empty() {
                in_word = prev.is_alphanumeric();
            }
            cur.push(c);
        } else if !cur.is_empty() {
            let t = cur
                .trim_end_matches(['.', ','])
                .trim_start_matches(['.', ',']);
            if !in_word && !c.is_alphanumeric() && t.chars().any(|c| c.is_ascii_digit()) {
                out.push(t.to_string());
            }
            cur.clear();
        }
        prev = c;
    }
    out
}

/// The text of the figure that ends at byte `end` of `line` (just before " dB"): a number, and
/// before it any numbers joined to it by `-`, `–` or ` / `.
fn figure_before(line: &str, end: usize) -> Option<String> {
    let head = &line[..end];
    let mut start = head.len();
    loop {
        // One number.
        let num_start = head[..start]
            .char_indices()
            .rev()
            .take_while(|&(_, c)| is_num_char(c))
            .last()
            .map(|(i, _)| i)?;
        if !head[num_start..start].chars().any(|c| c.is_ascii_digit()) {
            return None;
        }
        start = num_start;
        // A joint to an earlier number, if any.
        let before = &head[..start];
        let joint = ["-", "–", " / "].iter().find(|j| {
            before.ends_with(*j)
                && before[..before.len() - j.len()].ends_with(|c: char| c.is_ascii_digit())
        });
        match joint {
            Some(j) => start -= j.len(),
            None => break,
        }
    }
    Some(head[start..].to_string())
}

/// Every figure in dB in the README, by the rule in the module's doc.
fn readme_figures(readme: &str) -> Vec<Figure> {
    let mut out = Vec::new();
    for (i, line) in readme.lines().enumerate() {
        // "N dB" anywhere.
        let mut from = 0;
        while let Some(k) = line[from..].find(" dB") {
            let at = from + k;
            from = at + 3;
            let after = line[at + 3..].chars().next();
            if after.is_some_and(|c| c.is_alphanumeric() || c == '/') {
                continue;
            }
            if let Some(text) = figure_before(line, at) {
                out.push(Figure {
                    line: i + 1,
                    numbers: numbers(&text),
                    text: format!("\"{text} dB\""),
                });
            }
        }
        // Table rows with a "(dB)" cell: every number in the cells after it.
        if line.trim_start().starts_with('|') {
            let cells: Vec<&str> = line.split('|').collect();
            if let Some(k) = cells.iter().position(|c| c.contains("(dB)")) {
                let label = cells[k].trim();
                for cell in &cells[k + 1..] {
                    let nums = numbers(cell);
                    if !nums.is_empty() {
                        out.push(Figure {
                            line: i + 1,
                            text: format!(
                                "{} in the \"{label}\" row",
                                cell.trim().trim_matches('*')
                            ),
                            numbers: nums,
                        });
                    }
                }
            }
        }
    }
    out
}

/// The numbers BENCHMARKS.md gives as figures in dB: those in a line that says dB, or in a row
/// of a table whose header says dB.
fn page_db_numbers(page: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut table_in_db = None::<bool>;
    for line in page.lines() {
        let is_row = line.trim_start().starts_with('|');
        if !is_row {
            table_in_db = None;
        } else if table_in_db.is_none() {
            table_in_db = Some(line.contains("dB"));
        }
        if line.contains("dB") || (is_row && table_in_db == Some(true)) {
            out.extend(numbers(&without_dates(line)));
        }
    }
    out
}

/// One complaint per README figure whose numbers are not all on the page.
fn missing_figures(readme: &str, page: &str) -> Vec<String> {
    let on_page = page_db_numbers(page);
    readme_figures(readme)
        .into_iter()
        .filter_map(|f| {
            let missing: Vec<&String> =
                f.numbers.iter().filter(|n| !on_page.contains(*n)).collect();
            (!missing.is_empty()).then(|| {
                let missing: Vec<&str> = missing.iter().map(|s| s.as_str()).collect();
                format!(
                    "README.md:{}: {}: {} not on BENCHMARKS.md",
                    f.line,
                    f.text,
                    missing.join(", ")
                )
            })
        })
        .collect()
}

/// `## ` sections of the page without a date or without a command.
fn sections_without_provenance(page: &str) -> Vec<String> {
    let mut sections: Vec<(String, String)> = Vec::new();
    for line in page.lines() {
        if let Some(title) = line.strip_prefix("## ") {
            // The title counts: "## Fuzzing (2026-11-25)" carries its date.
            sections.push((title.to_string(), format!("{title}\n")));
        } else if let Some((_, body)) = sections.last_mut() {
            body.push_str(line);
            body.push('\n');
        }
    }
    let mut out = Vec::new();
    for (title, body) in &sections {
        let mut lacks = Vec::new();
        if !has_date(body) {
            lacks.push("a date (YYYY-MM-DD)");
        }
        if !has_command(body) {
            lacks.push("a command (`cargo ...`, `kodama-dag ...`, `scripts/...`, ...)");
        }
        if !lacks.is_empty() {
            out.push(format!(
                "BENCHMARKS.md, \"## {title}\": lacks {}",
                lacks.join(" and ")
            ));
        }
    }
    out
}

/// Byte offsets of the dates (YYYY-MM-DD) in `s`.
fn dates(s: &str) -> Vec<usize> {
    let b = s.as_bytes();
    let d = |i: usize| b.get(i).is_some_and(u8::is_ascii_digit);
    (0..b.len())
        .filter(|&i| {
            (0..4).all(|k| d(i + k))
                && b.get(i + 4) == Some(&b'-')
                && d(i + 5)
                && d(i + 6)
                && b.get(i + 7) == Some(&b'-')
                && d(i + 8)
                && d(i + 9)
                && !(i > 0 && d(i - 1))
                && !d(i + 10)
        })
        .collect()
}

fn has_date(s: &str) -> bool {
    !dates(s).is_empty()
}

/// `s` with its dates blanked, so that 2026-11-23 does not count as the numbers 2026, 11, 23.
fn without_dates(s: &str) -> String {
    let mut b = s.as_bytes().to_vec();
    for i in dates(s) {
        b[i..i + 10].fill(b' ');
    }
    String::from_utf8(b).expect("only ASCII digits and dashes were blanked")
}

fn has_command(s: &str) -> bool {
    const STARTS: [&str; 6] = [
        "cargo ",
        "kodama-dag ",
        "scripts/",
        "python3 ",
        "/usr/bin/time ",
        "FUZZ_SECONDS=",
    ];
    // Inline code spans: the text between a pair of backticks.
    s.split('`')
        .skip(1)
        .step_by(2)
        .any(|code| STARTS.iter().any(|p| code.starts_with(p)))
}

fn read(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn every_db_figure_in_the_readme_is_on_the_benchmarks_page() {
    let readme = read("README.md");
    let figures = readme_figures(&readme);
    assert!(
        figures.len() >= 9,
        "found only {} dB figures in README.md: has Table 1 moved out of a \"(dB)\" row?",
        figures.len()
    );
    let missing = missing_figures(&readme, &read("BENCHMARKS.md"));
    assert!(
        missing.is_empty(),
        "\n{}\n\nREADME.md quotes only the current figures, which live on BENCHMARKS.md (a number \
         counts there when it stands in a line that says dB, or in a table whose header says \
         dB). Quote the figure as BENCHMARKS.md gives it; or, for a new measurement, put it on \
         BENCHMARKS.md with its command, machine and date, and its story in \
         docs/benchmarks-log.md under \"## YYYY-MM-DD, commit <hash>: what was measured\".\n",
        missing.join("\n")
    );
}

#[test]
fn every_benchmarks_section_says_when_and_how() {
    let bad = sections_without_provenance(&read("BENCHMARKS.md"));
    assert!(
        bad.is_empty(),
        "\n{}\n\nEvery section of BENCHMARKS.md says when its figures were measured (YYYY-MM-DD) \
         and with which command (in backticks), so a reader can measure them again.\n",
        bad.join("\n")
    );
}

#[test]
fn the_rule_reads_figures_as_written() {
    let f = readme_figures(
        "a 5.78 dB twin, 5.77-6.86 dB, 0.21 / 7.6 dB, 9.1–23.1 dB, 0.02 dB/m, 3 dBm, (+2.0 dB)\n\
         | synthetic | P2P RMSE (dB) | **7.81** | 18.94 |\n",
    );
    let got: Vec<(usize, Vec<&str>)> = f
        .iter()
        .map(|f| (f.line, f.numbers.iter().map(|s| s.as_str()).collect()))
        .collect();
    assert_eq!(
        got,
        vec![
            (1, vec!["5.78"]),
            (1, vec!["5.77", "6.86"]),
            (1, vec!["0.21", "7.6"]),
            (1, vec!["9.1", "23.1"]),
            (1, vec!["2.0"]),
            (2, vec!["7.81"]),
            (2, vec!["18.94"]),
        ]
    );
    assert_eq!(
        numbers("2,909 cells, 0.40 / 0.27 dB."),
        vec!["2,909", "0.40", "0.27"]
    );
    assert_eq!(numbers("rx23, commit 2c95b20, 10^6 rays"), vec!["10", "6"]);
    assert_eq!(
        numbers(&without_dates("2026-11-23: 0.59-0.62")),
        vec!["0.59", "0.62"]
    );
}

#[test]
fn a_figure_the_page_does_not_give_is_named_with_its_line() {
    let page = "## Radio (2026-11-27)\n\n`kodama-dag sweep s.ron`: full twin 5.78 dB\n\n\
                | twin | P2P (dB) |\n|---|---|\n| seeds | 6.17 |\n\nTimes: 6.1 s\n";
    assert!(missing_figures("scores 5.78 dB, mean 6.17 dB", page).is_empty());
    assert_eq!(
        missing_figures("intro\nthe twin scores 6.1 dB", page),
        vec!["README.md:2: \"6.1 dB\": 6.1 not on BENCHMARKS.md"]
    );
    assert_eq!(
        missing_figures("| site | P2P RMSE (dB) | 5.78 | 19.0 |", page),
        vec!["README.md:1: 19.0 in the \"P2P RMSE (dB)\" row: 19.0 not on BENCHMARKS.md"]
    );
    assert!(sections_without_provenance(page).is_empty());
    assert_eq!(
        sections_without_provenance("## Speed\n\n`cargo bench`: 3 s\n"),
        vec!["BENCHMARKS.md, \"## Speed\": lacks a date (YYYY-MM-DD)"]
    );
}

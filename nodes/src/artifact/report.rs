//! A report: a folder of files (Markdown, CSV, JSON, PNG plots) made by the `Report` stage.

use serde::{Deserialize, Serialize};

/// Files by relative path; the first is the entry point (`report.md`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReportFiles {
    /// (relative path, bytes).
    pub files: Vec<(String, Vec<u8>)>,
}

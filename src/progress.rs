//! What the user sees while a graph runs: indicatif bars on a terminal, one plain line per event
//! otherwise (CI logs, pipes), nothing but warnings with `--quiet`. Everything goes to stderr;
//! stdout is reserved for `--json`.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::record::{NodeRecord, Status};

/// How to report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Progress bars (stderr is a terminal).
    Bars,
    /// One line per node that ran, failed or was skipped.
    Lines,
    /// Warnings and errors only.
    Quiet,
}

impl Mode {
    /// Bars on a terminal, lines otherwise; quiet if asked.
    pub fn detect(quiet: bool) -> Mode {
        if quiet {
            Mode::Quiet
        } else if std::io::stderr().is_terminal() {
            Mode::Bars
        } else {
            Mode::Lines
        }
    }
}

/// Where a reporter's lines go instead of stderr (the Python package hands them to
/// `sys.stderr`, which a notebook shows under the cell).
pub type Sink = Arc<dyn Fn(&str) + Send + Sync>;

/// The run's reporter.
pub struct Reporter {
    mode: Mode,
    multi: MultiProgress,
    overall: Option<ProgressBar>,
    done: AtomicUsize,
    sink: Option<Sink>,
}

impl Reporter {
    /// A reporter for a run of `total` nodes.
    pub fn new(mode: Mode, total: usize) -> Reporter {
        let multi = MultiProgress::with_draw_target(ProgressDrawTarget::stderr());
        let overall = (mode == Mode::Bars).then(|| {
            let bar = multi.add(ProgressBar::new(total as u64));
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix:>8.bold} [{bar:30}] {pos}/{len} nodes {elapsed} {msg}",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar.set_prefix("graph");
            bar.enable_steady_tick(Duration::from_millis(200));
            bar
        });
        Reporter {
            mode,
            multi,
            overall,
            done: AtomicUsize::new(0),
            sink: None,
        }
    }

    /// A reporter in lines (or, with `quiet`, warnings only) that hands each line to `sink`; a
    /// running stage that says how much work it has also gets a line at every tenth of it.
    pub fn with_sink(quiet: bool, total: usize, sink: Sink) -> Reporter {
        let mode = if quiet { Mode::Quiet } else { Mode::Lines };
        Reporter {
            sink: Some(sink),
            ..Reporter::new(mode, total)
        }
    }

    fn line(&self, text: &str) {
        let text = &for_terminal(text);
        match &self.sink {
            Some(sink) => sink(text),
            None if self.mode == Mode::Bars => {
                let _ = self.multi.println(text);
            }
            None => eprintln!("{text}"),
        }
    }

    /// A warning, shown in every mode.
    pub fn warn(&self, msg: &str) {
        self.line(&format!("warning: {msg}"));
    }

    /// A node's stage starts running; the handle is its progress.
    pub fn started(&self, id: &str, kind: &str) -> NodeProgress<'_> {
        if self.mode == Mode::Lines {
            self.line(&format!("running  {id} ({kind})"));
        }
        NodeProgress {
            reporter: self,
            label: format!("{id} ({kind})"),
            bar: OnceLock::new(),
            tenths: Tenths::default(),
        }
    }

    /// A node is done, whatever happened to it.
    pub fn finished(&self, rec: &NodeRecord) {
        let n = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(bar) = &self.overall {
            bar.set_position(n as u64);
        }
        let status = match rec.status {
            Status::Ran => "ran",
            Status::Failed => "FAILED",
            Status::Skipped => "skipped",
            Status::Cutoff => "cutoff",
            Status::Cached => return,
        };
        let show = match self.mode {
            Mode::Quiet => rec.status == Status::Failed,
            _ => true,
        };
        if show {
            let mut text = format!(
                "{status:<8} {} ({}) {:.0} ms: {}",
                rec.id, rec.kind, rec.ms, rec.reason
            );
            if let Some(e) = &rec.error {
                text.push_str(&format!("\n         error: {e}"));
            }
            self.line(&text);
        }
    }

    /// The run is over: clear the bars and print a one-line summary.
    pub fn finish(&self, records: &[NodeRecord], seconds: f64) {
        if let Some(bar) = &self.overall {
            bar.finish_and_clear();
        }
        if self.mode == Mode::Quiet {
            return;
        }
        let count = |s: Status| records.iter().filter(|r| r.status == s).count();
        self.line(&format!(
            "{} nodes: {} ran, {} cached, {} cut off, {} failed, {} skipped in {seconds:.2} s",
            // The records, not `total`: a sweep's one reporter serves variants of any size.
            records.len(),
            count(Status::Ran),
            count(Status::Cached),
            count(Status::Cutoff),
            count(Status::Failed),
            count(Status::Skipped)
        ));
    }

    /// A line of a sweep or other command around runs: shown unless quiet.
    pub fn say(&self, text: &str) {
        if self.mode != Mode::Quiet {
            self.line(text);
        }
    }
}

/// A stage's work counted for a sink's tenth-by-tenth lines.
#[derive(Default)]
struct Tenths {
    total: AtomicU64,
    done: AtomicU64,
}

/// One running node's progress; a bar appears when the stage says how much work there is.
pub struct NodeProgress<'a> {
    reporter: &'a Reporter,
    label: String,
    bar: OnceLock<ProgressBar>,
    tenths: Tenths,
}

impl kodama_nodes::Progress for NodeProgress<'_> {
    fn set_total(&self, total: u64) {
        if self.reporter.sink.is_some() {
            self.tenths.total.store(total, Ordering::Relaxed);
            self.tenths.done.store(0, Ordering::Relaxed);
        }
        if self.reporter.mode != Mode::Bars {
            return;
        }
        let bar = self.bar.get_or_init(|| {
            let bar = self.reporter.multi.add(ProgressBar::new(total));
            bar.set_style(
                ProgressStyle::with_template(
                    "  {msg:30!} [{bar:30.cyan/blue}] {percent:>3}% {eta}",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar.set_message(self.label.clone());
            bar
        });
        bar.set_length(total);
    }
    fn advance(&self, n: u64) {
        if let Some(bar) = self.bar.get() {
            bar.inc(n);
        }
        if self.reporter.sink.is_none() || self.reporter.mode != Mode::Lines {
            return;
        }
        let total = self.tenths.total.load(Ordering::Relaxed);
        if total > 0 {
            let before = self.tenths.done.fetch_add(n, Ordering::Relaxed);
            let (was, now) = (before * 10 / total, (before + n).min(total) * 10 / total);
            if now > was {
                self.reporter
                    .line(&format!("         {} {}%", self.label, now * 10));
            }
        }
    }
    fn warn(&self, message: &str) {
        self.reporter.warn(&format!("{}: {message}", self.label));
    }
}

impl Drop for NodeProgress<'_> {
    fn drop(&mut self) {
        if let Some(bar) = self.bar.get() {
            bar.finish_and_clear();
            self.reporter.multi.remove(bar);
        }
    }
}

/// The progress of one long command outside a graph (`trace`, `radiomap`): a bar when the amount
/// of work is known, else a spinner, both with the elapsed time, on a terminal; one line per step
/// elsewhere.
pub struct Task {
    mode: Mode,
    bar: Option<ProgressBar>,
}

impl Task {
    /// Starts a task: `what` it does, and how many steps when known.
    pub fn new(mode: Mode, what: &str, total: Option<u64>) -> Task {
        let bar = (mode == Mode::Bars).then(|| {
            let (bar, template) = match total {
                Some(n) => (
                    ProgressBar::with_draw_target(Some(n), ProgressDrawTarget::stderr()),
                    "{spinner} {msg} [{bar:30}] {pos}/{len} {elapsed} (eta {eta})",
                ),
                None => (
                    ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr()),
                    "{spinner} {msg} {elapsed}",
                ),
            };
            bar.set_style(
                ProgressStyle::with_template(template)
                    .expect("valid template")
                    .progress_chars("=> "),
            );
            bar.set_message(what.to_owned());
            bar.enable_steady_tick(Duration::from_millis(100));
            bar
        });
        if mode == Mode::Lines {
            eprintln!("{}", for_terminal(what));
        }
        Task { mode, bar }
    }

    /// `n` more steps done.
    pub fn advance(&self, n: u64) {
        if let Some(bar) = &self.bar {
            bar.inc(n);
        }
    }

    /// Now doing `what`.
    pub fn step(&self, what: &str) {
        match &self.bar {
            Some(bar) => bar.set_message(what.to_owned()),
            None if self.mode == Mode::Lines => eprintln!("{}", for_terminal(what)),
            None => {}
        }
    }
}

impl Drop for Task {
    fn drop(&mut self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// The longest line printed whole; past it a line is cut and what was cut is counted.
pub const MAX_LINE_CHARS: usize = 2000;

/// The longest error a run record keeps: the record is read by programs (`--json`, the run
/// records), which get more than a terminal line but not a file's worth.
pub const MAX_RECORD_CHARS: usize = 20_000;

/// `text` of at most `max` characters: past that its middle is left out and counted, so both
/// the start of a message and its end (where an error says what was expected) stay.
pub fn cut(text: &str, max: usize) -> String {
    let n = text.chars().count();
    if n <= max {
        return text.to_string();
    }
    let head = max / 2;
    let tail = max - head;
    let at = |k: usize| text.char_indices().nth(k).map_or(text.len(), |(i, _)| i);
    format!(
        "{} ... ({} characters left out) ... {}",
        &text[..at(head)],
        n - head - tail,
        &text[at(n - tail)..]
    )
}

/// `text` as it may reach a terminal: control characters other than newline and tab written as
/// escapes (`\u{1b}`), so a node id or a file's content echoed in an error cannot move the cursor
/// or retitle the window; and every line kept to [`MAX_LINE_CHARS`] characters, its middle left
/// out and counted (a CSV header of 500,000 columns once made an error line of 8.8 MB).
pub fn for_terminal(text: &str) -> String {
    let mut out = String::with_capacity(text.len().min(8 * MAX_LINE_CHARS));
    for (i, line) in text.split('\n').enumerate() {
        if i > 0 {
            out.push('\n');
        }
        for c in cut(line, MAX_LINE_CHARS).chars() {
            if c.is_control() && c != '\t' {
                out.extend(c.escape_default());
            } else {
                out.push(c);
            }
        }
    }
    out
}

//! Progress bars for long phases (indicatif), silenced by `--quiet`; bars draw on stderr only when it is a
//! terminal, so logs and CI output stay clean.

use indicatif::{ProgressBar, ProgressStyle};

/// Writes one line to stderr (warnings, summaries, the final error), ignoring write errors: `eprintln!`
/// panics when stderr is closed (`2>&-`) or a closed pipe, and a message must never crash the run.
pub fn stderr_line(line: std::fmt::Arguments) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}

/// Creates progress bars, or hidden ones when quiet.
#[derive(Clone, Copy, Debug, Default)]
pub struct Progress {
    pub quiet: bool,
}

impl Progress {
    pub fn new(quiet: bool) -> Self {
        Progress { quiet }
    }

    /// A bar counting `len` steps of `phase`.
    pub fn bar(&self, len: u64, phase: &str) -> ProgressBar {
        if self.quiet {
            return ProgressBar::hidden();
        }
        let bar = ProgressBar::new(len);
        bar.set_style(
            ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {msg} ({elapsed})")
                .expect("static template")
                .progress_chars("=> "),
        );
        bar.set_prefix(phase.to_string());
        bar
    }

    /// A spinner for a phase of unknown length.
    pub fn spinner(&self, phase: &str) -> ProgressBar {
        if self.quiet {
            return ProgressBar::hidden();
        }
        let bar = ProgressBar::new_spinner();
        bar.set_style(
            ProgressStyle::with_template("{prefix:>10} {spinner} {msg} ({elapsed})")
                .expect("static template"),
        );
        bar.set_prefix(phase.to_string());
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        bar
    }
}

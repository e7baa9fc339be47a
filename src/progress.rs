//! Progress bars for long phases (indicatif), silenced by `--quiet`.

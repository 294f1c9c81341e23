//! `railfuse results`: the sources' experiments re-run over several seeds, each written as a
//! page of the book from rows of data: the prose in a template per page (`pages/*.md`), every
//! table through one writer ([`table::Table`]).
//!
//! - [`sources`]: sources 000 and 001, the long runs, α and β (docs/results.md);
//! - [`safety`]: source 002 (docs/safety.md); [`gnss_ins`]: source 003 (docs/gnss_ins.md);
//!   [`eddy_current`]: source 004 (docs/eddy_current.md); [`tuning`]: docs/tuning.md.

use anyhow::{Context, Result};

mod eddy_current;
mod gnss_ins;
mod page;
mod safety;
mod sources;
mod table;
mod tuning;

pub use page::Args;

pub fn run(a: Args) -> Result<()> {
    // Minutes of runs must not end in "cannot write": the page is checked first.
    super::check_writable(&page::page(&a))?;
    std::fs::create_dir_all(&a.dir)
        .with_context(|| format!("{}: cannot create", a.dir.display()))?;
    match () {
        _ if a.safety => safety::run(&a),
        _ if a.gnss_ins => gnss_ins::run(&a),
        _ if a.eddy_current => eddy_current::run(&a),
        _ if a.tuning => tuning::run(&a),
        _ => sources::run(&a),
    }
}

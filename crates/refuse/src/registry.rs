//! The pipeline kinds a configuration may name beyond the four estimators along the track:
//! one line each in [`Registry::standard`]. A program can add its own kind with
//! [`Registry::with`] and parse a configuration against that registry
//! ([`Pipelines::parse_with`](crate::spec::Pipelines::parse_with)).

use std::sync::Arc;

use crate::kinds::PipelineKind;

/// The kinds a configuration may name.
#[derive(Clone)]
pub struct Registry {
    kinds: Vec<Arc<dyn PipelineKind>>,
}

impl Registry {
    /// railfuse's kinds: one line each.
    pub fn standard() -> Self {
        Self { kinds: Vec::new() }
            .with(crate::safety::Kind)
            .with(crate::gnss_ins::Kind)
            .with(crate::eddy_current::Kind)
    }

    /// This registry and `kind` (which replaces a kind of the same name).
    pub fn with(mut self, kind: impl PipelineKind + 'static) -> Self {
        self.kinds.retain(|k| k.name() != kind.name());
        self.kinds.push(Arc::new(kind));
        self
    }

    pub fn get(&self, name: &str) -> Option<&dyn PipelineKind> {
        self.kinds.iter().find(|k| k.name() == name).map(|k| &**k)
    }

    /// The kind whose settings table is `section`.
    pub fn by_section(&self, section: &str) -> Option<&dyn PipelineKind> {
        self.kinds
            .iter()
            .find(|k| k.section() == section)
            .map(|k| &**k)
    }

    pub fn kinds(&self) -> impl Iterator<Item = &dyn PipelineKind> + '_ {
        self.kinds.iter().map(|k| &**k)
    }

    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.kinds.iter().map(|k| k.name())
    }

    pub fn sections(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.kinds.iter().map(|k| k.section())
    }
}

impl Default for Registry {
    fn default() -> Self {
        Self::standard()
    }
}

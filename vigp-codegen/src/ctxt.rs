//! The error collector: validation reports every mistake it finds, each a
//! spanned `syn::Error`, combined into one error at the end.

use proc_macro2::Span;
use std::fmt::Display;

/// Spanned errors gathered while checking a description.
#[derive(Default)]
pub struct Ctxt(Option<syn::Error>);

impl Ctxt {
    /// Report `msg` at `span`.
    pub fn push(&mut self, span: Span, msg: impl Display) {
        self.add(syn::Error::new(span, msg));
    }

    /// Report an error built elsewhere (it keeps its own span).
    pub fn add(&mut self, e: syn::Error) {
        match &mut self.0 {
            Some(all) => all.combine(e),
            None => self.0 = Some(e),
        }
    }

    /// The value of a fallible check, or `None` after reporting its error.
    pub fn ok<T>(&mut self, r: syn::Result<T>) -> Option<T> {
        r.map_err(|e| self.add(e)).ok()
    }

    /// Stop here if anything was reported: the errors so far, combined.
    pub fn check(&mut self) -> syn::Result<()> {
        match self.0.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// `ok` when nothing was reported, else every error combined.
    pub fn finish<T>(mut self, ok: T) -> syn::Result<T> {
        self.check().map(|()| ok)
    }
}

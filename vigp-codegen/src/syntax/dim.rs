//! Which grammar a description is read with: planar or spatial, chosen
//! from the tokens of its `gravity` before parsing.

use proc_macro2::{Delimiter, TokenStream, TokenTree};

/// Which description a mechanism is: its gravity has two components
/// (or none) or three.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dim {
    /// Bodies in a plane: points `[x, y]`.
    Planar,
    /// Rigid bodies in space: points `[x, y, z]`.
    Spatial,
}

impl Dim {
    /// [`Dim::Spatial`] when the description's `gravity` has three
    /// components. Scans the tokens only; the planar checks report every
    /// other shape of `gravity`.
    pub fn of(input: &TokenStream) -> Dim {
        let Some(body) = input.clone().into_iter().find_map(|t| match t {
            TokenTree::Group(g) if g.delimiter() == Delimiter::Brace => Some(g.stream()),
            _ => None,
        }) else {
            return Dim::Planar;
        };
        let tokens: Vec<TokenTree> = body.into_iter().collect();
        for w in tokens.windows(3) {
            if let (TokenTree::Ident(key), TokenTree::Punct(colon), TokenTree::Group(g)) =
                (&w[0], &w[1], &w[2])
                && key == "gravity"
                && colon.as_char() == ':'
                && g.delimiter() == Delimiter::Bracket
            {
                return if components(g.stream()) == 3 {
                    Dim::Spatial
                } else {
                    Dim::Planar
                };
            }
        }
        Dim::Planar
    }

    /// The named points on a link.
    pub fn anchors(self) -> &'static [&'static str] {
        match self {
            Dim::Planar => &["start", "end", "center"],
            Dim::Spatial => &["start", "end", "center", "com"],
        }
    }

    /// How a point's coordinates are written.
    pub fn point(self) -> &'static str {
        match self {
            Dim::Planar => "[x, y]",
            Dim::Spatial => "[x, y, z]",
        }
    }
}

/// Number of comma-separated items (a trailing comma does not count).
fn components(stream: TokenStream) -> usize {
    let mut count = 0;
    let mut item = false;
    for t in stream {
        match t {
            TokenTree::Punct(p) if p.as_char() == ',' => {
                if item {
                    count += 1;
                }
                item = false;
            }
            _ => item = true,
        }
    }
    count + usize::from(item)
}

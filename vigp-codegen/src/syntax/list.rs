//! Comma-separated lists, for parsers that carry the grammar's dimension.

use syn::Token;
use syn::parse::ParseStream;

/// Items separated by commas, a trailing comma allowed (as
/// `ParseBuffer::parse_terminated`, for parsers that capture a `Dim`).
pub(super) fn terminated<T>(
    input: ParseStream,
    mut item: impl FnMut(ParseStream) -> syn::Result<T>,
) -> syn::Result<Vec<T>> {
    let mut out = Vec::new();
    while !input.is_empty() {
        out.push(item(input)?);
        if input.is_empty() {
            break;
        }
        input.parse::<Token![,]>()?;
    }
    Ok(out)
}

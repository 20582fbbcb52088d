//! The mechanism descriptions of the crate's own sources, as text.

/// The text inside every `<marker> … }` of `src`, where `marker` ends with
/// the opening brace (`"crate::mechanism! {"`, or `"mechanism! {"` for any
/// path): up to the matching closing brace.
pub fn mechanism_bodies<'a>(src: &'a str, marker: &str) -> Vec<&'a str> {
    let mut out = Vec::new();
    let mut rest = src;
    while let Some(i) = rest.find(marker) {
        let body = &rest[i + marker.len()..];
        let mut depth = 1;
        let mut end = body.len();
        for (k, ch) in body.char_indices() {
            match ch {
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
            if depth == 0 {
                end = k;
                break;
            }
        }
        out.push(&body[..end]);
        rest = &body[end..];
    }
    out
}

/// [`mechanism_bodies`] of every `mechanism! {` with the name of the
/// mechanism each declares (its `pub Name {` line).
pub fn named_bodies(src: &str) -> Vec<(String, String)> {
    mechanism_bodies(src, "mechanism! {")
        .into_iter()
        .map(|body| {
            let name = body
                .lines()
                .map(str::trim)
                .find(|l| l.starts_with("pub "))
                .and_then(|l| l.split_whitespace().nth(1))
                .expect("a `pub Name {` line")
                .to_string();
            (name, body.to_string())
        })
        .collect()
}

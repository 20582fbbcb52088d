//! The font of every example's figures, shared by `#[path]` (each example is
//! its own crate): DejaVu Sans embedded in the binary and registered as
//! plotters' `"sans-serif"`, so that no system font library is needed.

use std::error::Error;
use std::sync::OnceLock;

/// The family name the figures ask plotters for.
pub const FONT: &str = "sans-serif";

/// Registers DejaVu Sans (embedded) as plotters' [`FONT`], once per process.
pub fn register_embedded_font() -> Result<(), Box<dyn Error>> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    static DEJAVU_SANS: &[u8] = include_bytes!(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../assets/fonts/DejaVuSans.ttf"
    ));
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT, plotters::style::FontStyle::Normal, DEJAVU_SANS)
                .map_err(|_| "the embedded DejaVu Sans font is not a valid TTF".to_string())
        })
        .clone()
        .map_err(Into::into)
}

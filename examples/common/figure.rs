//! Writing a figure as SVG and PNG, shared by `#[path]` between the
//! examples that draw several figures (`paper`, `work_precision`).

use plotters::coord::Shift;
use plotters::prelude::*;
use std::error::Error;
use std::path::{Path, PathBuf};

/// A figure that draws itself on any plotters backend.
pub trait Draw {
    /// Draws the whole figure on `root`.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), Box<dyn Error>>
    where
        DB::ErrorType: 'static;
}

/// Writes `<stem>.svg` and `<stem>.png` of `size` pixels into `dir`; returns
/// their paths.
pub fn write_svg_png(
    figure: &impl Draw,
    size: (u32, u32),
    dir: &Path,
    stem: &str,
) -> Result<Vec<PathBuf>, Box<dyn Error>> {
    let svg = dir.join(format!("{stem}.svg"));
    let png = dir.join(format!("{stem}.png"));
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        figure.draw(&root)?;
        root.present()?;
    }
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        figure.draw(&root)?;
        root.present()?;
    }
    Ok(vec![svg, png])
}

/// Smallest and largest of the finite positive `values` (the extent of a log
/// axis), or `None` when there is none.
pub fn positive_extent(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.filter(|v| v.is_finite() && *v > 0.0).fold(
        None,
        |acc: Option<(f64, f64)>, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        },
    )
}

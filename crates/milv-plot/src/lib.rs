//! # milv-plot — simple PNG charts for reports and debugging
//!
//! Three pure functions, each validating its input and writing one PNG (white background):
//!
//! | function | what | size |
//! |---|---|---|
//! | [`histogram_png`] | counts of `values` in equal bins over `[min, max]`; NaN/±inf skipped and counted in the title | [`CHART_SIZE`] |
//! | [`lines_png`] | one polyline per [`Series`], legend for the first [`LEGEND_MAX`] | [`CHART_SIZE`] |
//! | [`heatmap_png`] | a row-major matrix as a viridis-like colour map with a colour bar, optional (row, col) path on top (DTW) | [`HEATMAP_SIZE`] |
//!
//! Drawing is `plotters` with its bitmap backend; the PNG is encoded with the workspace
//! `image` crate (plotters' own encoder would pull in a second, older `image`).
//!
//! Text: plotters' `ab_glyph` renderer, which never looks at system fonts (no font-kit,
//! no fontconfig). The first chart of the process reads a TTF — [`DEFAULT_FONT`], from the
//! Debian package [`FONT_PACKAGE`], or the file named by the env var [`FONT_ENV`] — and
//! registers it as `sans-serif`. A missing file is [`Error::FontUnreadable`], never a panic.
//!
//! `cargo run -p milv-plot --example demo -- DIR` writes one chart of each kind to look at.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

/// Font used when [`FONT_ENV`] is unset.
pub const DEFAULT_FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
/// Debian package that installs [`DEFAULT_FONT`] (listed in `tools/setup.sh`).
pub const FONT_PACKAGE: &str = "fonts-dejavu-core";
/// Env var overriding the font file (any TrueType/OpenType file).
pub const FONT_ENV: &str = "MILV_FONT";
/// Size of histogram and line charts, in pixels.
pub const CHART_SIZE: (u32, u32) = (900, 600);
/// Size of heatmaps: wider than tall by the colour bar, so the matrix itself is about square.
pub const HEATMAP_SIZE: (u32, u32) = (880, 800);
/// Series beyond this many are drawn but not listed in the legend (it would cover the plot).
pub const LEGEND_MAX: usize = 12;

/// Why a chart could not be written.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(
        "cannot read font file {path}: {source} (the default {DEFAULT_FONT} comes from the \
         Debian package {FONT_PACKAGE}: `apt-get install {FONT_PACKAGE}`; or set {FONT_ENV} to a .ttf)"
    )]
    FontUnreadable {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("font file {path} is not a TrueType/OpenType font (set {FONT_ENV} to a .ttf)")]
    FontInvalid { path: PathBuf },
    #[error("nothing to plot: {0}")]
    Empty(&'static str),
    #[error("heatmap has {len} values, {rows}x{cols} needs {}", rows.saturating_mul(*cols))]
    ShapeMismatch { len: usize, rows: usize, cols: usize },
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    #[error("drawing failed: {0}")]
    Draw(String),
    #[error("cannot write PNG {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
}

/// One named line for [`lines_png`]; points are joined in the given order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

const FONT_FAMILY: &str = "sans-serif";
const TITLE_PX: u32 = 24;
const DESC_PX: u32 = 16;
const LABEL_PX: u32 = 13;
// matplotlib's tab:blue.
const BAR_COLOR: RGBColor = RGBColor(31, 119, 180);
// Red stands out on every viridis shade.
const OVERLAY_COLOR: RGBColor = RGBColor(230, 30, 30);
const NAN_COLOR: RGBColor = RGBColor(160, 160, 160);
// matplotlib tab10: distinct and readable on white; the first ten series use these.
const TAB10: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Whether the font is registered; plotters keeps fonts in a process-global table.
static FONT_READY: Mutex<bool> = Mutex::new(false);

/// Registers the chart font once per process.
fn ensure_font() -> Result<(), Error> {
    let mut ready = FONT_READY.lock().unwrap_or_else(PoisonError::into_inner);
    if *ready {
        return Ok(());
    }
    let path = match std::env::var_os(FONT_ENV) {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => PathBuf::from(DEFAULT_FONT),
    };
    let bytes = std::fs::read(&path).map_err(|source| Error::FontUnreadable {
        path: path.clone(),
        source,
    })?;
    // register_font wants &'static bytes; leaking one font file once per process is the cost.
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    register_font(FONT_FAMILY, FontStyle::Normal, bytes).map_err(|_| Error::FontInvalid { path })?;
    *ready = true;
    Ok(())
}

fn draw_err(e: impl std::fmt::Display) -> Error {
    Error::Draw(e.to_string())
}

fn font(px: u32) -> TextStyle<'static> {
    (FONT_FAMILY, px).into_font().into()
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Renders into an RGB buffer via `draw`, then encodes it as PNG at `path`.
fn render_png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> Result<(), Error>,
) -> Result<(), Error> {
    ensure_font()?;
    let mut buf = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        draw(&root)?;
        root.present().map_err(draw_err)?;
    }
    image::save_buffer_with_format(
        path,
        &buf,
        w,
        h,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|source| Error::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// `[lo, hi]` widened by 5 % each side; a single value gets a unit-ish window around it.
fn padded(lo: f64, hi: f64) -> (f64, f64) {
    let span = hi - lo;
    let pad = if span > 0.0 {
        span * 0.05
    } else {
        (lo.abs() * 0.05).max(0.5)
    };
    (lo - pad, hi + pad)
}

fn min_max(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// Histogram of `values` with `bins` equal bins over `[min, max]` of the finite values
/// (last bin closed, as numpy). Non-finite values are skipped and their count appended to
/// the title. All-equal values get one bin-range of width 1 centred on them.
///
/// Errors: [`Error::Empty`] without a finite value, [`Error::InvalidArgument`] for `bins == 0`.
pub fn histogram_png(
    path: &Path,
    values: &[f64],
    bins: usize,
    title: &str,
    x_label: &str,
) -> Result<(), Error> {
    if bins == 0 {
        return Err(Error::InvalidArgument("bins must be at least 1".into()));
    }
    let (lo, hi) = min_max(values.iter().copied().filter(|v| v.is_finite()))
        .ok_or(Error::Empty("histogram has no finite values"))?;
    let skipped = values.iter().filter(|v| !v.is_finite()).count();
    let (lo, hi) = if hi > lo { (lo, hi) } else { (lo - 0.5, hi + 0.5) };
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0u32; bins];
    for v in values.iter().filter(|v| v.is_finite()) {
        // `as usize` saturates; the min() puts v == hi into the last bin.
        let i = (((v - lo) / width) as usize).min(bins - 1);
        counts[i] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(0);
    let y_max = top + (top / 10).max(1);
    let title = if skipped > 0 {
        format!("{title} ({skipped} non-finite skipped)")
    } else {
        title.to_string()
    };
    render_png(path, CHART_SIZE, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(&title, font(TITLE_PX))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(lo..hi, 0u32..y_max)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc(x_label)
            .y_desc("count")
            .axis_desc_style(font(DESC_PX))
            .label_style(font(LABEL_PX))
            .draw()
            .map_err(draw_err)?;
        chart
            .draw_series(counts.iter().enumerate().filter(|(_, c)| **c > 0).map(|(i, &c)| {
                let x0 = lo + width * i as f64;
                Rectangle::new([(x0, 0), (x0 + width, c)], BAR_COLOR.filled())
            }))
            .map_err(draw_err)?;
        Ok(())
    })
}

/// Colour of series `i`: tab10 first, then the darker Palette99 entries (the light ones
/// vanish on white).
fn series_color(i: usize) -> RGBColor {
    if let Some(c) = TAB10.get(i) {
        return *c;
    }
    let dark: Vec<RGBColor> = Palette99::COLORS
        .iter()
        .filter(|(r, g, b)| 299 * u32::from(*r) + 587 * u32::from(*g) + 114 * u32::from(*b) < 180_000)
        .map(|&(r, g, b)| RGBColor(r, g, b))
        .collect();
    dark[(i - TAB10.len()) % dark.len()]
}

/// One line per series (all drawn), a legend naming the first [`LEGEND_MAX`], axis ranges
/// from the finite points plus a 5 % margin. Non-finite points are dropped.
///
/// Errors: [`Error::Empty`] when no series has a finite point.
pub fn lines_png(
    path: &Path,
    series: &[Series],
    title: &str,
    x_label: &str,
    y_label: &str,
) -> Result<(), Error> {
    let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let all = || series.iter().flat_map(|s| s.points.iter().filter(finite));
    let (x_lo, x_hi) = min_max(all().map(|p| p.0)).ok_or(Error::Empty("no finite points"))?;
    let (y_lo, y_hi) = min_max(all().map(|p| p.1)).ok_or(Error::Empty("no finite points"))?;
    let (x_lo, x_hi) = padded(x_lo, x_hi);
    let (y_lo, y_hi) = padded(y_lo, y_hi);
    render_png(path, CHART_SIZE, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, font(TITLE_PX))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(80)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .axis_desc_style(font(DESC_PX))
            .label_style(font(LABEL_PX))
            .draw()
            .map_err(draw_err)?;
        for (i, s) in series.iter().enumerate() {
            let color = series_color(i);
            let anno = chart
                .draw_series(LineSeries::new(
                    s.points.iter().filter(finite).copied(),
                    color.stroke_width(2),
                ))
                .map_err(draw_err)?;
            if i < LEGEND_MAX {
                anno.label(s.name.as_str())
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2)));
            }
        }
        if series.len() > LEGEND_MAX {
            // A label without a legend mark: says the legend is truncated.
            chart
                .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                .map_err(draw_err)?
                .label(format!("… {} more", series.len() - LEGEND_MAX));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(font(LABEL_PX))
            .draw()
            .map_err(draw_err)?;
        Ok(())
    })
}

// Viridis sampled at t = 0, 1/8, …, 1 (matplotlib); linear in between is visually faithful.
const VIRIDIS: [(f64, f64, f64); 9] = [
    (68.0, 1.0, 84.0),
    (71.0, 44.0, 122.0),
    (59.0, 81.0, 139.0),
    (44.0, 113.0, 142.0),
    (33.0, 144.0, 141.0),
    (39.0, 173.0, 129.0),
    (92.0, 200.0, 99.0),
    (170.0, 220.0, 50.0),
    (253.0, 231.0, 37.0),
];

/// Viridis-like colour for `t` in [0, 1] (clamped): dark purple at 0, yellow at 1.
fn viridis(t: f64) -> RGBColor {
    let x = t.clamp(0.0, 1.0) * (VIRIDIS.len() - 1) as f64;
    let i = (x as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    let mix = |p: f64, q: f64| (p + (q - p) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Cell-edge ticks are whole numbers: print them without a trailing ".0".
fn index_label(v: &f64) -> String {
    if v.fract() == 0.0 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

/// For each pixel in `edges[0]..edges[n]` (edges ascending), the cell it falls in.
fn cell_of_pixel(edges: &[i32]) -> Vec<usize> {
    let n = edges.len() - 1;
    (edges[0]..edges[n])
        .map(|p| edges.partition_point(|&e| e <= p).saturating_sub(1).min(n - 1))
        .collect()
}

/// `values` (row-major, `rows × cols`) as a colour map, row 0 at the top, column 0 at the
/// left, low = dark; non-finite cells grey. A colour bar on the right maps colour to value.
/// `path_overlay`, if given, is a polyline through the centres of its `(row, col)` cells
/// (e.g. a DTW warping path over its cost matrix). Each matrix pixel is sampled from its
/// cell, so huge matrices cost no more than small ones.
///
/// Errors: [`Error::Empty`] for 0 rows or cols, [`Error::ShapeMismatch`] when
/// `values.len() != rows * cols`, [`Error::InvalidArgument`] for an overlay cell outside.
#[allow(clippy::too_many_arguments)] // the signature is the crate's agreed API
pub fn heatmap_png(
    path: &Path,
    values: &[f64],
    rows: usize,
    cols: usize,
    title: &str,
    x_label: &str,
    y_label: &str,
    path_overlay: Option<&[(usize, usize)]>,
) -> Result<(), Error> {
    if rows == 0 || cols == 0 {
        return Err(Error::Empty("heatmap has zero rows or columns"));
    }
    if rows.checked_mul(cols) != Some(values.len()) {
        return Err(Error::ShapeMismatch {
            len: values.len(),
            rows,
            cols,
        });
    }
    let overlay = path_overlay.unwrap_or(&[]);
    if let Some(&(r, c)) = overlay.iter().find(|&&(r, c)| r >= rows || c >= cols) {
        return Err(Error::InvalidArgument(format!(
            "overlay cell ({r}, {c}) is outside the {rows}x{cols} matrix"
        )));
    }
    let (v_lo, v_hi) = min_max(values.iter().copied().filter(|v| v.is_finite())).unwrap_or((0.0, 1.0));
    let span = v_hi - v_lo;
    let color_of = |v: f64| {
        if !v.is_finite() {
            NAN_COLOR
        } else if span > 0.0 {
            viridis((v - v_lo) / span)
        } else {
            viridis(0.5)
        }
    };
    render_png(path, HEATMAP_SIZE, |root| {
        let body = root.titled(title, font(TITLE_PX)).map_err(draw_err)?;
        let (left, right) = body.split_horizontally(HEATMAP_SIZE.0 - 110);
        // Same top margin and bottom label area on both sides keep matrix and bar aligned.
        let mut chart = ChartBuilder::on(&left)
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(70)
            // Reversed y range puts row 0 at the top, as a matrix is printed.
            .build_cartesian_2d(0f64..cols as f64, rows as f64..0f64)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels((cols + 1).min(11))
            .y_labels((rows + 1).min(11))
            .x_label_formatter(&index_label)
            .y_label_formatter(&index_label)
            .x_desc(x_label)
            .y_desc(y_label)
            .axis_desc_style(font(DESC_PX))
            .label_style(font(LABEL_PX))
            .draw()
            .map_err(draw_err)?;
        let x_edges: Vec<i32> = (0..=cols)
            .map(|c| chart.backend_coord(&(c as f64, 0.0)).0)
            .collect();
        let y_edges: Vec<i32> = (0..=rows)
            .map(|r| chart.backend_coord(&(0.0, r as f64)).1)
            .collect();
        let col_at = cell_of_pixel(&x_edges);
        let row_at = cell_of_pixel(&y_edges);
        for (py, &r) in (y_edges[0]..).zip(&row_at) {
            for (px, &c) in (x_edges[0]..).zip(&col_at) {
                root.draw_pixel((px, py), &color_of(values[r * cols + c]))
                    .map_err(draw_err)?;
            }
        }
        if !overlay.is_empty() {
            chart
                .draw_series(LineSeries::new(
                    overlay.iter().map(|&(r, c)| (c as f64 + 0.5, r as f64 + 0.5)),
                    OVERLAY_COLOR.stroke_width(2),
                ))
                .map_err(draw_err)?;
        }

        // Colour bar: value axis on the right, gradient filled row by row.
        let (bar_lo, bar_hi) = if span > 0.0 {
            (v_lo, v_hi)
        } else {
            padded(v_lo, v_hi)
        };
        let mut bar = ChartBuilder::on(&right)
            .margin(15)
            .margin_left(5)
            .x_label_area_size(50)
            .right_y_label_area_size(60)
            .build_cartesian_2d(0f64..1f64, bar_lo..bar_hi)
            .map_err(draw_err)?;
        bar.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_labels(6)
            .label_style(font(LABEL_PX))
            .draw()
            .map_err(draw_err)?;
        let (x0, top) = bar.backend_coord(&(0.0, bar_hi));
        let (x1, bottom) = bar.backend_coord(&(1.0, bar_lo));
        for py in top..=bottom {
            let t = if bottom > top {
                f64::from(bottom - py) / f64::from(bottom - top)
            } else {
                0.5
            };
            root.draw(&Rectangle::new([(x0, py), (x1, py + 1)], viridis(t).filled()))
                .map_err(draw_err)?;
        }
        Ok(())
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn load(path: &Path) -> image::RgbImage {
        image::open(path).unwrap().to_rgb8()
    }

    fn count(img: &image::RgbImage, f: impl Fn([u8; 3]) -> bool) -> usize {
        img.pixels().filter(|p| f(p.0)).count()
    }

    fn rgb(c: RGBColor) -> [u8; 3] {
        [c.0, c.1, c.2]
    }

    const WHITE_PX: [u8; 3] = [255, 255, 255];

    #[test]
    fn histogram_draws_bars() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("h.png");
        let values: Vec<f64> = (0..1000)
            .map(|i| ((i * 37) % 101) as f64 / 10.0)
            .chain([f64::NAN])
            .collect();
        histogram_png(&out, &values, 20, "hist", "value").unwrap();
        let img = load(&out);
        assert_eq!(img.dimensions(), CHART_SIZE);
        let total = (CHART_SIZE.0 * CHART_SIZE.1) as usize;
        assert!(count(&img, |p| p == WHITE_PX) > total / 4);
        // Uniform data: the bars fill most of the plot area.
        assert!(count(&img, |p| p == rgb(BAR_COLOR)) > total / 4);
    }

    #[test]
    fn histogram_all_equal_and_single_bin() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("h.png");
        histogram_png(&out, &[3.0; 10], 5, "same", "x").unwrap();
        let img = load(&out);
        assert!(count(&img, |p| p == rgb(BAR_COLOR)) > 1000);
        histogram_png(&out, &[1.0, 2.0, 3.0], 1, "one bin", "x").unwrap();
        assert!(count(&load(&out), |p| p == rgb(BAR_COLOR)) > 10_000);
    }

    #[test]
    fn histogram_errors() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("h.png");
        assert!(matches!(
            histogram_png(&out, &[], 10, "t", "x"),
            Err(Error::Empty(_))
        ));
        assert!(matches!(
            histogram_png(&out, &[f64::NAN, f64::INFINITY], 10, "t", "x"),
            Err(Error::Empty(_))
        ));
        assert!(matches!(
            histogram_png(&out, &[1.0], 0, "t", "x"),
            Err(Error::InvalidArgument(_))
        ));
        assert!(!out.exists());
    }

    #[test]
    fn lines_draw_each_series() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("l.png");
        let series: Vec<Series> = (0..15)
            .map(|k| Series {
                name: format!("s{k}"),
                points: (0..50)
                    .map(|i| (i as f64, (i as f64 * 0.2 + k as f64).sin() + k as f64))
                    .collect(),
            })
            .collect();
        lines_png(&out, &series, "lines", "t", "y").unwrap();
        let img = load(&out);
        assert_eq!(img.dimensions(), CHART_SIZE);
        assert!(count(&img, |p| p == WHITE_PX) > 100_000);
        for k in [0, 1, 9, 14] {
            let n = count(&img, |p| p == rgb(series_color(k)));
            assert!(n > 200, "series {k}: {n} pixels");
        }
    }

    #[test]
    fn lines_single_point_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("l.png");
        let one = Series {
            name: "flat".into(),
            points: vec![(1.0, 2.0), (1.0, 2.0)],
        };
        lines_png(&out, &[one], "flat", "x", "y").unwrap();
        assert_eq!(load(&out).dimensions(), CHART_SIZE);
        assert!(matches!(
            lines_png(&out, &[], "t", "x", "y"),
            Err(Error::Empty(_))
        ));
        let empty = Series {
            name: "e".into(),
            points: vec![(f64::NAN, 1.0)],
        };
        assert!(matches!(
            lines_png(&out, &[empty], "t", "x", "y"),
            Err(Error::Empty(_))
        ));
    }

    #[test]
    fn heatmap_with_overlay() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("m.png");
        let (rows, cols) = (30, 40);
        let values: Vec<f64> = (0..rows * cols)
            .map(|i| ((i / cols) + (i % cols)) as f64)
            .collect();
        let path: Vec<(usize, usize)> = (0..rows).map(|r| (r, r * (cols - 1) / (rows - 1))).collect();
        heatmap_png(&out, &values, rows, cols, "cost", "j", "i", Some(&path)).unwrap();
        let img = load(&out);
        assert_eq!(img.dimensions(), HEATMAP_SIZE);
        assert!(count(&img, |p| p == WHITE_PX) > 50_000);
        // Lowest cell (top-left) is viridis(0), highest (bottom-right) viridis(1).
        assert!(count(&img, |p| p == rgb(viridis(0.0))) > 100);
        assert!(count(&img, |p| p == rgb(viridis(1.0))) > 100);
        assert!(count(&img, |p| p == rgb(OVERLAY_COLOR)) > 500);
        // Many distinct shades, not a flat fill.
        let shades: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
        assert!(shades.len() > 50);
        // The colour bar: a strip of coloured (non-grey) pixels right of the matrix.
        let bar = (HEATMAP_SIZE.0 - 100..HEATMAP_SIZE.0)
            .flat_map(|x| (0..HEATMAP_SIZE.1).map(move |y| (x, y)))
            .filter(|&(x, y)| {
                let [r, g, b] = img.get_pixel(x, y).0;
                !(r == g && g == b)
            })
            .count();
        assert!(bar > 5000, "colour bar has {bar} coloured pixels");
    }

    #[test]
    fn heatmap_large_and_constant() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("m.png");
        heatmap_png(&out, &vec![1.0; 1500 * 1200], 1500, 1200, "big", "x", "y", None).unwrap();
        let img = load(&out);
        assert!(count(&img, |p| p == rgb(viridis(0.5))) > 200_000);
        heatmap_png(
            &out,
            &[0.0, 1.0, f64::NAN, 2.0],
            2,
            2,
            "tiny",
            "x",
            "y",
            Some(&[]),
        )
        .unwrap();
        assert!(count(&load(&out), |p| p == rgb(NAN_COLOR)) > 10_000);
    }

    #[test]
    fn heatmap_errors() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("m.png");
        assert!(matches!(
            heatmap_png(&out, &[1.0; 5], 2, 3, "t", "x", "y", None),
            Err(Error::ShapeMismatch {
                len: 5,
                rows: 2,
                cols: 3
            })
        ));
        assert!(matches!(
            heatmap_png(&out, &[], 0, 3, "t", "x", "y", None),
            Err(Error::Empty(_))
        ));
        assert!(matches!(
            heatmap_png(&out, &[1.0; 4], 2, 2, "t", "x", "y", Some(&[(0, 0), (2, 1)])),
            Err(Error::InvalidArgument(_))
        ));
        assert!(!out.exists());
    }

    #[test]
    fn viridis_ends_and_cells() {
        assert_eq!(rgb(viridis(-1.0)), [68, 1, 84]);
        assert_eq!(rgb(viridis(2.0)), [253, 231, 37]);
        assert_eq!(cell_of_pixel(&[10, 12, 15]), vec![0, 0, 1, 1, 1]);
    }
}

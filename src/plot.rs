//! Figures for reports: a small data model (a [`Figure`] is a grid of
//! [`Panel`]s; an XY panel holds [`Series`] and an optional shaded [`Band`],
//! other panels are grouped bar charts or annotated matrices such as a MAC
//! matrix) that does not depend on the drawing library, and [`save`], which
//! renders a figure with plotters to both PNG and SVG.
//!
//! Robustness rules applied when drawing:
//! - non-finite points (NaN, ±Inf, and magnitudes above 1e300) are skipped;
//!   in lines they break the line into separate pieces;
//! - empty series are allowed (they still get a legend entry);
//! - a range with no spread (all values equal) is padded so the axis is valid;
//! - long series are decimated for drawing only: consecutive points falling in
//!   the same pixel column are replaced by at most four (first, minimum,
//!   maximum, last), which is invisible at the output resolution and keeps a
//!   200 000-point time history to a few thousand drawn points.
//!
//! Text needs a TrueType font, read at run time (no system font library is
//! used): `TACIT_FONT` if set, then common system paths (Debian's
//! `fonts-dejavu-core` first), then any `.ttf` under the usual font folders.

use crate::error::{Result, TacitError};
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Colours given to series (and bar groups) in order of appearance within a
/// panel, as RGB; the 9th series reuses the 1st colour.
pub const PALETTE: [(u8, u8, u8); 8] = [
    (31, 119, 180),  // blue
    (214, 39, 40),   // red
    (44, 160, 44),   // green
    (255, 127, 14),  // orange
    (148, 103, 189), // purple
    (140, 86, 75),   // brown
    (227, 119, 194), // pink
    (23, 190, 207),  // cyan
];

/// Values whose magnitude exceeds this are treated like NaN (skipped), so
/// that axis spans cannot overflow.
const MAX_MAGNITUDE: f64 = 1e300;
/// Font family name under which the run-time font is registered.
const FAMILY: &str = "sans-serif";
const FIGURE_TITLE_SIZE: f64 = 20.0;
const PANEL_TITLE_SIZE: f64 = 15.0;
const AXIS_DESC_SIZE: f64 = 13.0;
const TICK_SIZE: f64 = 11.0;
const LEGEND_SIZE: f64 = 11.0;
/// Space reserved for the figure title, in pixels.
const TITLE_HEIGHT: u32 = 40;
/// Smallest panel, in pixels, that can hold axes, labels and a plot.
const MIN_PANEL: (u32, u32) = (120, 100);
/// Above this many dashes a dashed series is drawn solid (dashes are separate
/// paths, which would bloat the SVG and are invisible in such dense data).
const MAX_DASHES: f64 = 6000.0;
const DASH: i32 = 6;
const DASH_GAP: i32 = 4;
const MARKER_RADIUS: i32 = 2;
/// Light grid lines between two labelled ones.
const LIGHT_LINES: usize = 4;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SeriesStyle {
    /// Solid line.
    #[default]
    Line,
    /// Dashed line (drawn solid when the data are so dense that dashes would
    /// not be visible anyway).
    DashedLine,
    /// Small filled circles, no line.
    Points,
}

/// One curve of an XY panel. Its colour is chosen automatically from
/// [`PALETTE`] by its position in [`Panel::series`] unless `colour` is set.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Legend text; an empty label gives no legend entry.
    pub label: String,
    /// Abscissae; must have the same length as `y`.
    pub x: Vec<f64>,
    /// Ordinates.
    pub y: Vec<f64>,
    /// Line, dashed line or points.
    pub style: SeriesStyle,
    /// Colour as RGB; None takes the [`PALETTE`] colour of the series'
    /// position.
    pub colour: Option<(u8, u8, u8)>,
}

impl Series {
    /// A series with the given style.
    pub fn new(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>, style: SeriesStyle) -> Self {
        Series {
            label: label.into(),
            x,
            y,
            style,
            colour: None,
        }
    }
    /// The same series in the colour `rgb`.
    pub fn with_colour(mut self, rgb: (u8, u8, u8)) -> Self {
        self.colour = Some(rgb);
        self
    }
    /// A solid line.
    pub fn line(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self::new(label, x, y, SeriesStyle::Line)
    }
    /// A dashed line.
    pub fn dashed(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self::new(label, x, y, SeriesStyle::DashedLine)
    }
    /// Points without a line.
    pub fn points(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self::new(label, x, y, SeriesStyle::Points)
    }
}

/// A shaded area between `lo` and `hi` (e.g. a ±2σ band), drawn under the
/// series of an XY panel in translucent grey.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Band {
    /// Abscissae; `x`, `lo` and `hi` must have the same length.
    pub x: Vec<f64>,
    /// Lower edge.
    pub lo: Vec<f64>,
    /// Upper edge.
    pub hi: Vec<f64>,
    /// Legend text; empty gives no legend entry.
    pub label: String,
}

impl Band {
    /// A band from its two edges.
    pub fn new(label: impl Into<String>, x: Vec<f64>, lo: Vec<f64>, hi: Vec<f64>) -> Self {
        Band {
            x,
            lo,
            hi,
            label: label.into(),
        }
    }
    /// The band `centre ± half_width` (e.g. mean ± 2σ). The shorter of
    /// `x`, `centre` and `half_width` sets the length.
    pub fn around(label: impl Into<String>, x: &[f64], centre: &[f64], half_width: &[f64]) -> Self {
        let n = x.len().min(centre.len()).min(half_width.len());
        let lo = (0..n).map(|i| centre[i] - half_width[i].abs()).collect();
        let hi = (0..n).map(|i| centre[i] + half_width[i].abs()).collect();
        Band::new(label, x[..n].to_vec(), lo, hi)
    }
}

/// What a panel shows.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum PanelKind {
    /// Curves ([`Panel::series`]) and an optional band ([`Panel::band`]).
    #[default]
    Xy,
    /// Grouped bar chart: one group of bars per category, one bar per group
    /// entry, side by side (e.g. the adjustment of each spring in % found by
    /// several methods). `Panel::series` and `Panel::band` are ignored.
    Bars {
        /// Category names along the x axis.
        categories: Vec<String>,
        /// (group name, one value per category); NaN values give no bar.
        groups: Vec<(String, Vec<f64>)>,
    },
    /// Annotated matrix (e.g. a MAC matrix): cells shaded from white (0) to
    /// dark blue (1), values clamped to 0..1 for the shading, each cell
    /// printed with its value when the cells are large enough to hold it.
    /// Row 0 is at the top. `Panel::series` and `Panel::band` are ignored.
    Matrix {
        /// Rows of equal length.
        values: Vec<Vec<f64>>,
        /// One label per row, or empty for 1, 2, 3, …
        row_labels: Vec<String>,
        /// One label per column, or empty for 1, 2, 3, …
        col_labels: Vec<String>,
    },
}

/// One plot of a figure.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Panel {
    /// Caption above the plot; may be empty.
    pub title: String,
    /// Axis description below the plot.
    pub x_label: String,
    /// Axis description left of the plot.
    pub y_label: String,
    /// Curves of an XY panel.
    pub series: Vec<Series>,
    /// Shaded area of an XY panel.
    pub band: Option<Band>,
    /// XY plot, bar chart or matrix.
    pub kind: PanelKind,
}

impl Panel {
    /// An XY panel.
    pub fn xy(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        series: Vec<Series>,
    ) -> Self {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series,
            band: None,
            kind: PanelKind::Xy,
        }
    }

    /// The same panel with a shaded band.
    pub fn with_band(mut self, band: Band) -> Self {
        self.band = Some(band);
        self
    }

    /// A grouped bar chart panel (see [`PanelKind::Bars`]).
    pub fn bars(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        categories: Vec<String>,
        groups: Vec<(String, Vec<f64>)>,
    ) -> Self {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            kind: PanelKind::Bars { categories, groups },
            ..Default::default()
        }
    }

    /// A matrix panel (see [`PanelKind::Matrix`]); `x_label` describes the
    /// columns, `y_label` the rows.
    pub fn matrix(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        values: Vec<Vec<f64>>,
        row_labels: Vec<String>,
        col_labels: Vec<String>,
    ) -> Self {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            kind: PanelKind::Matrix {
                values,
                row_labels,
                col_labels,
            },
            ..Default::default()
        }
    }
}

/// A figure: a title on top and panels laid out row by row in a grid of
/// `columns` columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// Title above all panels; empty for none.
    pub title: String,
    /// Panels, filled row by row.
    pub panels: Vec<Panel>,
    /// Number of grid columns (0 is taken as 1; more than the number of
    /// panels is reduced to it).
    pub columns: usize,
    /// Width of the whole figure in pixels.
    pub width: u32,
    /// Height of the whole figure in pixels, title included.
    pub height: u32,
}

impl Figure {
    /// A figure sized for its grid: 800×500 for a single panel, otherwise
    /// 560×400 per panel, plus 40 pixels for a title.
    pub fn new(title: impl Into<String>, panels: Vec<Panel>, columns: usize) -> Self {
        let mut fig = Figure {
            title: title.into(),
            panels,
            columns,
            width: 0,
            height: 0,
        };
        let (rows, cols) = fig.grid();
        fig.width = if cols == 1 { 800 } else { 560 * cols as u32 };
        fig.height = if rows == 1 { 500 } else { 400 * rows as u32 };
        if !fig.title.trim().is_empty() {
            fig.height += TITLE_HEIGHT;
        }
        fig
    }

    /// A figure holding one panel.
    pub fn single(title: impl Into<String>, panel: Panel) -> Self {
        Figure::new(title, vec![panel], 1)
    }

    /// (rows, columns) of the panel grid; at least 1×1.
    pub fn grid(&self) -> (usize, usize) {
        let n = self.panels.len().max(1);
        let cols = self.columns.clamp(1, n);
        (n.div_ceil(cols), cols)
    }
}

/// A panel of time histories sharing the time vector `t` (x axis "time [s]").
/// Each entry is (label, values, style); values must have the length of `t`.
pub fn time_panel(
    title: &str,
    y_label: &str,
    t: &[f64],
    series: Vec<(String, Vec<f64>, SeriesStyle)>,
) -> Panel {
    let series = series
        .into_iter()
        .map(|(label, y, style)| Series::new(label, t.to_vec(), y, style))
        .collect();
    Panel::xy(title, "time [s]", y_label, series)
}

/// A one-panel figure with a grouped bar chart: for each category one bar per
/// entry of `values` (name, one value per category), side by side. The width
/// grows with the number of bars.
pub fn bar_chart(
    title: &str,
    categories: &[String],
    values: &[(String, Vec<f64>)],
    y_label: &str,
) -> Figure {
    let panel = Panel::bars("", "", y_label, categories.to_vec(), values.to_vec());
    let mut fig = Figure::single(title, panel);
    let bars = categories.len() * values.len().max(1);
    let wanted = 140 + 14 * bars as u32 + 24 * categories.len() as u32;
    fig.width = fig.width.max(wanted.min(3000));
    fig
}

/// Render `fig` to `stem.png` and `stem.svg` (the extensions are appended to
/// `stem`), each written atomically; returns the two paths. The directory
/// must exist. Fails on inconsistent data (e.g. `x` and `y` of different
/// lengths), on a figure too small for its grid, when no font can be found,
/// or when a file cannot be written.
pub fn save(fig: &Figure, stem: &Path) -> Result<Vec<PathBuf>> {
    validate(fig)?;
    ensure_font()?;
    let png = with_suffix(stem, ".png");
    let svg = with_suffix(stem, ".svg");

    crate::io::write_atomic(&png, |tmp| {
        // The bitmap backend picks the image format from the extension, so
        // render next to the temporary file under a `.png` name, then rename.
        let tmp_png = with_suffix(tmp, ".png");
        let res = render_png(fig, &tmp_png)
            .map_err(|m| render_error(&png, m))
            .and_then(|()| std::fs::rename(&tmp_png, tmp).map_err(|e| TacitError::io(tmp, e)));
        if res.is_err() {
            let _ = std::fs::remove_file(&tmp_png);
        }
        res
    })?;

    let text = render_svg(fig).map_err(|m| render_error(&svg, m))?;
    crate::io::write_string(&svg, &text)?;
    Ok(vec![png, svg])
}

/// Render `fig` as an SVG document (e.g. to embed in an HTML report).
pub fn to_svg(fig: &Figure) -> Result<String> {
    validate(fig)?;
    ensure_font()?;
    render_svg(fig)
        .map_err(|m| TacitError::Setting(format!("rendering figure '{}': {m}", fig.title)))
}

// ---------------------------------------------------------------- checks

fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

fn render_error(path: &Path, message: String) -> TacitError {
    TacitError::io(
        path,
        std::io::Error::other(format!("rendering plot: {message}")),
    )
}

fn validate(fig: &Figure) -> Result<()> {
    let name = if fig.title.is_empty() {
        "<untitled>"
    } else {
        fig.title.as_str()
    };
    let bad = |msg: String| Err(TacitError::Setting(format!("figure '{name}': {msg}")));
    let (rows, cols) = fig.grid();
    let title_h = if fig.title.trim().is_empty() {
        0
    } else {
        TITLE_HEIGHT
    };
    let pw = fig.width / cols as u32;
    let ph = fig.height.saturating_sub(title_h) / rows as u32;
    if pw < MIN_PANEL.0 || ph < MIN_PANEL.1 {
        return bad(format!(
            "size {}×{} leaves {pw}×{ph} pixels per panel for a {rows}×{cols} grid \
             (minimum {}×{})",
            fig.width, fig.height, MIN_PANEL.0, MIN_PANEL.1
        ));
    }
    for (p, panel) in fig.panels.iter().enumerate() {
        let at = format!("panel {} '{}'", p + 1, panel.title);
        match &panel.kind {
            PanelKind::Xy => {
                for s in &panel.series {
                    if s.x.len() != s.y.len() {
                        return bad(format!(
                            "{at}, series '{}': {} x values but {} y values",
                            s.label,
                            s.x.len(),
                            s.y.len()
                        ));
                    }
                }
                if let Some(b) = &panel.band {
                    if b.lo.len() != b.x.len() || b.hi.len() != b.x.len() {
                        return bad(format!(
                            "{at}, band '{}': {} x, {} lo and {} hi values",
                            b.label,
                            b.x.len(),
                            b.lo.len(),
                            b.hi.len()
                        ));
                    }
                }
            }
            PanelKind::Bars { categories, groups } => {
                for (g, v) in groups {
                    if v.len() != categories.len() {
                        return bad(format!(
                            "{at}, bar group '{g}': {} values for {} categories",
                            v.len(),
                            categories.len()
                        ));
                    }
                }
            }
            PanelKind::Matrix {
                values,
                row_labels,
                col_labels,
            } => {
                let nc = values.first().map_or(0, Vec::len);
                if let Some((r, row)) = values.iter().enumerate().find(|(_, r)| r.len() != nc) {
                    return bad(format!(
                        "{at}: matrix row {} has {} values, row 1 has {nc}",
                        r + 1,
                        row.len()
                    ));
                }
                if !row_labels.is_empty() && row_labels.len() != values.len() {
                    return bad(format!(
                        "{at}: {} row labels for {} rows",
                        row_labels.len(),
                        values.len()
                    ));
                }
                if !col_labels.is_empty() && col_labels.len() != nc {
                    return bad(format!(
                        "{at}: {} column labels for {nc} columns",
                        col_labels.len()
                    ));
                }
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------- font

static FONT: OnceLock<std::result::Result<(), String>> = OnceLock::new();

/// Register a TrueType font for plot text, once per process.
fn ensure_font() -> Result<()> {
    FONT.get_or_init(load_font)
        .clone()
        .map_err(TacitError::Setting)
}

fn load_font() -> std::result::Result<(), String> {
    for path in font_candidates() {
        let Ok(bytes) = std::fs::read(&path) else {
            continue;
        };
        if !looks_like_font(&bytes) {
            continue;
        }
        // plotters keeps fonts for the life of the process.
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        if plotters::style::register_font(FAMILY, FontStyle::Normal, bytes).is_err() {
            continue;
        }
        if let Some(bold) = bold_sibling(&path) {
            if let Ok(b) = std::fs::read(&bold) {
                if looks_like_font(&b) {
                    let b: &'static [u8] = Box::leak(b.into_boxed_slice());
                    let _ = plotters::style::register_font(FAMILY, FontStyle::Bold, b);
                }
            }
        }
        return Ok(());
    }
    Err(
        "no usable TrueType font found for plot text; install fonts-dejavu-core \
         (Debian/Ubuntu) or set TACIT_FONT=/path/to/font.ttf"
            .to_string(),
    )
}

fn looks_like_font(b: &[u8]) -> bool {
    b.len() > 12
        && matches!(
            &b[..4],
            [0, 1, 0, 0] | b"true" | b"OTTO" | b"ttcf" | b"typ1"
        )
}

fn bold_sibling(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?.to_str()?;
    let bold = if name.contains("Regular") {
        name.replacen("Regular", "Bold", 1)
    } else {
        let (stem, ext) = name.rsplit_once('.')?;
        format!("{stem}-Bold.{ext}")
    };
    let p = path.with_file_name(bold);
    p.is_file().then_some(p)
}

fn font_candidates() -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = Vec::new();
    if let Some(p) = std::env::var_os("TACIT_FONT") {
        out.push(PathBuf::from(p));
    }
    for p in [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
        "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
        "/usr/local/share/fonts/DejaVuSans.ttf",
        "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
        "/usr/share/fonts/liberation-sans/LiberationSans-Regular.ttf",
        "/usr/share/fonts/truetype/freefont/FreeSans.ttf",
        "/usr/share/fonts/truetype/noto/NotoSans-Regular.ttf",
        "/System/Library/Fonts/Supplemental/Arial.ttf",
        "/Library/Fonts/Arial.ttf",
        "C:\\Windows\\Fonts\\arial.ttf",
    ] {
        out.push(PathBuf::from(p));
    }
    // Fallback: any TrueType/OpenType file in the usual folders, plain sans
    // faces first.
    let mut dirs = vec![
        PathBuf::from("/usr/share/fonts"),
        PathBuf::from("/usr/local/share/fonts"),
    ];
    if let Some(home) = std::env::var_os("HOME") {
        let home = PathBuf::from(home);
        dirs.push(home.join(".local/share/fonts"));
        dirs.push(home.join(".fonts"));
    }
    let mut found = Vec::new();
    for d in dirs {
        scan_fonts(&d, 5, &mut found);
    }
    found.sort_by_key(|p| (font_rank(p), p.clone()));
    out.extend(found);
    out
}

fn scan_fonts(dir: &Path, depth: usize, found: &mut Vec<PathBuf>) {
    if depth == 0 || found.len() > 5000 {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            scan_fonts(&p, depth - 1, found);
        } else if p
            .extension()
            .and_then(|x| x.to_str())
            .is_some_and(|x| x.eq_ignore_ascii_case("ttf") || x.eq_ignore_ascii_case("otf"))
        {
            found.push(p);
        }
    }
}

/// Lower is better: regular sans faces before styled or symbol faces.
fn font_rank(p: &Path) -> u32 {
    let n = p
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let mut r = 0;
    if !n.contains("sans") {
        r += 1;
    }
    for bad in [
        "bold",
        "italic",
        "oblique",
        "mono",
        "condensed",
        "light",
        "math",
        "symbol",
        "emoji",
    ] {
        if n.contains(bad) {
            r += 2;
        }
    }
    r
}

// ---------------------------------------------------------------- render

type Draw<T = ()> = std::result::Result<T, String>;

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

fn render_png(fig: &Figure, path: &Path) -> Draw {
    let root = BitMapBackend::new(path, (fig.width, fig.height)).into_drawing_area();
    render(&root, fig)?;
    root.present().map_err(err)
}

fn render_svg(fig: &Figure) -> Draw<String> {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, (fig.width, fig.height)).into_drawing_area();
        render(&root, fig)?;
        root.present().map_err(err)?;
    }
    Ok(text)
}

fn font(size: f64) -> TextStyle<'static> {
    TextStyle::from((FAMILY, size).into_font()).color(&BLACK)
}

fn color(i: usize) -> RGBColor {
    let (r, g, b) = PALETTE[i % PALETTE.len()];
    RGBColor(r, g, b)
}

fn render<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &Figure) -> Draw {
    root.fill(&WHITE).map_err(err)?;
    let body = if fig.title.trim().is_empty() {
        root.clone()
    } else {
        let (top, rest) = root.split_vertically(TITLE_HEIGHT);
        let style = TextStyle::from((FAMILY, FIGURE_TITLE_SIZE, FontStyle::Bold).into_font())
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center));
        let (w, h) = top.dim_in_pixel();
        top.draw(&Text::new(
            fig.title.clone(),
            ((w / 2) as i32, (h / 2) as i32),
            style,
        ))
        .map_err(err)?;
        rest
    };
    let (rows, cols) = fig.grid();
    for (panel, area) in fig.panels.iter().zip(body.split_evenly((rows, cols))) {
        match &panel.kind {
            PanelKind::Xy => draw_xy(&area, panel)?,
            PanelKind::Bars { categories, groups } => draw_bars(&area, panel, categories, groups)?,
            PanelKind::Matrix {
                values,
                row_labels,
                col_labels,
            } => draw_matrix(&area, panel, values, row_labels, col_labels)?,
        }
    }
    Ok(())
}

fn ok(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_MAGNITUDE
}

/// Running minimum and maximum of finite values.
#[derive(Clone, Copy)]
struct Extent {
    lo: f64,
    hi: f64,
}

impl Extent {
    fn new() -> Self {
        Extent {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
        }
    }
    fn add(&mut self, v: f64) {
        if ok(v) {
            self.lo = self.lo.min(v);
            self.hi = self.hi.max(v);
        }
    }
    /// The axis range: `margin` (a fraction of the span) on each side; a
    /// range without spread is padded; no data gives 0..1.
    fn range(self, margin: f64) -> (f64, f64) {
        if self.lo > self.hi {
            return (0.0, 1.0);
        }
        let span = self.hi - self.lo;
        let scale = self.lo.abs().max(self.hi.abs());
        if span <= 1e-12 * scale || span == 0.0 {
            let pad = if scale == 0.0 { 1.0 } else { 0.05 * scale };
            return (self.lo - pad, self.hi + pad);
        }
        (self.lo - margin * span, self.hi + margin * span)
    }
}

/// Data to pixel mapping of a plotting area (only pixel *columns and rows*
/// are needed, for decimation).
struct PixelGrid {
    x0: f64,
    sx: f64,
    y0: f64,
    sy: f64,
    width: usize,
}

impl PixelGrid {
    fn new(x: (f64, f64), y: (f64, f64), dim: (u32, u32)) -> Self {
        PixelGrid {
            x0: x.0,
            sx: dim.0 as f64 / (x.1 - x.0),
            y0: y.0,
            sy: dim.1 as f64 / (y.1 - y.0),
            width: dim.0.max(1) as usize,
        }
    }
    fn col(&self, x: f64) -> i64 {
        ((x - self.x0) * self.sx).floor() as i64
    }
    fn row(&self, y: f64) -> i64 {
        ((y - self.y0) * self.sy).floor() as i64
    }
    /// Length in pixels of a polyline.
    fn length(&self, pts: &[(f64, f64)]) -> f64 {
        pts.windows(2)
            .map(|w| ((w[1].0 - w[0].0) * self.sx).hypot((w[1].1 - w[0].1) * self.sy))
            .sum()
    }
}

/// Split (x, y) at non-finite points into runs of finite points.
fn finite_runs(x: &[f64], y: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut cur = Vec::new();
    for (&a, &b) in x.iter().zip(y) {
        if ok(a) && ok(b) {
            cur.push((a, b));
        } else if !cur.is_empty() {
            runs.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        runs.push(cur);
    }
    runs
}

/// Min/max decimation of a polyline: each stretch of consecutive points in
/// the same pixel column becomes its first, lowest, highest and last point
/// (in their original order). Short runs are returned unchanged.
fn decimate(run: Vec<(f64, f64)>, grid: &PixelGrid) -> Vec<(f64, f64)> {
    if run.len() <= 2 * grid.width {
        return run;
    }
    let mut out = Vec::with_capacity(8 * grid.width);
    let flush = |idx: [usize; 4], out: &mut Vec<(f64, f64)>| {
        let mut idx = idx;
        idx.sort_unstable();
        let mut last = usize::MAX;
        for i in idx {
            if i != last {
                out.push(run[i]);
                last = i;
            }
        }
    };
    let mut col = grid.col(run[0].0);
    let (mut first, mut lo, mut hi, mut last) = (0, 0, 0, 0);
    for (i, &(x, y)) in run.iter().enumerate().skip(1) {
        let c = grid.col(x);
        if c != col {
            flush([first, lo, hi, last], &mut out);
            col = c;
            (first, lo, hi, last) = (i, i, i, i);
        } else {
            if y < run[lo].1 {
                lo = i;
            }
            if y > run[hi].1 {
                hi = i;
            }
            last = i;
        }
    }
    flush([first, lo, hi, last], &mut out);
    out
}

/// Finite points; for long series at most one per square of a marker
/// diameter (the first one falling in it).
fn thin_points(x: &[f64], y: &[f64], grid: &PixelGrid) -> Vec<(f64, f64)> {
    let pts = x
        .iter()
        .zip(y)
        .filter(|(a, b)| ok(**a) && ok(**b))
        .map(|(a, b)| (*a, *b));
    if x.len() <= grid.width {
        return pts.collect();
    }
    // One marker per cell of a marker diameter: invisible in dense clouds.
    let cell = 2 * MARKER_RADIUS.max(1) as i64;
    let mut seen = HashSet::new();
    pts.filter(|&(a, b)| seen.insert((grid.col(a) / cell, grid.row(b) / cell)))
        .collect()
}

/// Polygons of a band: one per run of finite (x, lo, hi); long runs are
/// reduced to the envelope (lowest lo, highest hi) of each pixel column.
fn band_polygons(band: &Band, grid: &PixelGrid) -> Vec<Vec<(f64, f64)>> {
    let mut runs: Vec<Vec<(f64, f64, f64)>> = Vec::new();
    let mut cur = Vec::new();
    for ((&x, &lo), &hi) in band.x.iter().zip(&band.lo).zip(&band.hi) {
        if ok(x) && ok(lo) && ok(hi) {
            cur.push((x, lo.min(hi), lo.max(hi)));
        } else if !cur.is_empty() {
            runs.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        runs.push(cur);
    }
    runs.into_iter()
        .filter(|r| r.len() >= 2)
        .map(|run| {
            let run = if run.len() > 2 * grid.width {
                let mut env: Vec<(f64, f64, f64)> = Vec::with_capacity(2 * grid.width + 2);
                let mut col = i64::MIN;
                for (x, lo, hi) in run {
                    let c = grid.col(x);
                    if c != col || env.len() < 2 {
                        // Each column keeps its first and last x with the
                        // column's envelope on both.
                        env.push((x, lo, hi));
                        env.push((x, lo, hi));
                        col = c;
                    } else {
                        let n = env.len();
                        let (l, h) = (env[n - 1].1.min(lo), env[n - 1].2.max(hi));
                        env[n - 2].1 = l;
                        env[n - 2].2 = h;
                        env[n - 1] = (x, l, h);
                    }
                }
                env
            } else {
                run
            };
            run.iter()
                .map(|&(x, lo, _)| (x, lo))
                .chain(run.iter().rev().map(|&(x, _, hi)| (x, hi)))
                .collect()
        })
        .collect()
}

fn legend_box<'a, DB: DrawingBackend + 'a, X: Ranged, Y: Ranged>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
) -> Draw {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .label_font(font(LEGEND_SIZE))
        .draw()
        .map_err(err)
}

/// A line or dashed line series: its finite runs as paths, lone points as
/// dots (runs shorter than a pixel would be invisible as lines).
fn draw_line_series<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    s: &Series,
    c: RGBColor,
    line: ShapeStyle,
    grid: &PixelGrid,
) -> Draw {
    let label = s.label.as_str();
    let (runs, lone): (Vec<_>, Vec<_>) = finite_runs(&s.x, &s.y)
        .into_iter()
        .partition(|r| grid.length(r) >= 1.0);
    // Isolated finite points (between NaNs) and runs shorter than
    // a pixel would be invisible as lines: mark them with a dot.
    chart
        .draw_series(lone.into_iter().map(|r| Circle::new(r[0], 2, c.filled())))
        .map_err(err)?;
    let runs: Vec<_> = runs.into_iter().map(|r| decimate(r, grid)).collect();
    let dashes: f64 = runs.iter().map(|r| grid.length(r)).sum::<f64>() / f64::from(DASH + DASH_GAP);
    if s.style == SeriesStyle::DashedLine && dashes <= MAX_DASHES {
        let anno = chart
            .draw_series(
                runs.into_iter()
                    .map(|r| DashedPathElement::new(r, DASH, DASH_GAP, line)),
            )
            .map_err(err)?;
        if !label.is_empty() {
            anno.label(label).legend(move |(x, y)| {
                DashedPathElement::new(vec![(x, y), (x + 20, y)], 5, 3, line)
            });
        }
    } else {
        let anno = chart
            .draw_series(runs.into_iter().map(|r| PathElement::new(r, line)))
            .map_err(err)?;
        if !label.is_empty() {
            anno.label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], line));
        }
    }
    Ok(())
}

/// The x and y extents of a panel's finite points and band.
fn xy_extent(panel: &Panel) -> (Extent, Extent) {
    let mut ex = Extent::new();
    let mut ey = Extent::new();
    for s in &panel.series {
        for (&x, &y) in s.x.iter().zip(&s.y) {
            if ok(x) && ok(y) {
                ex.add(x);
                ey.add(y);
            }
        }
    }
    if let Some(b) = &panel.band {
        for ((&x, &lo), &hi) in b.x.iter().zip(&b.lo).zip(&b.hi) {
            if ok(x) && ok(lo) && ok(hi) {
                ex.add(x);
                ey.add(lo);
                ey.add(hi);
            }
        }
    }
    (ex, ey)
}

fn draw_xy<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, panel: &Panel) -> Draw {
    let (ex, ey) = xy_extent(panel);
    let has_points = panel.series.iter().any(|s| s.style == SeriesStyle::Points);
    let xr = ex.range(if has_points { 0.03 } else { 0.0 });
    let yr = ey.range(0.05);

    let mut builder = ChartBuilder::on(area);
    builder
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(66);
    if !panel.title.is_empty() {
        builder.caption(&panel.title, font(PANEL_TITLE_SIZE));
    }
    let mut chart = builder
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
        .map_err(err)?;
    let fx = |v: &f64| tick_label(*v, xr);
    let fy = |v: &f64| tick_label(*v, yr);
    chart
        .configure_mesh()
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .label_style(font(TICK_SIZE))
        .axis_desc_style(font(AXIS_DESC_SIZE))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(242, 242, 242))
        .max_light_lines(LIGHT_LINES)
        .draw()
        .map_err(err)?;
    let grid = PixelGrid::new(xr, yr, chart.plotting_area().dim_in_pixel());

    let mut labelled = false;
    if let Some(band) = &panel.band {
        let fill = RGBColor(120, 120, 120).mix(0.25).filled();
        let polys = band_polygons(band, &grid);
        let anno = chart
            .draw_series(polys.into_iter().map(|p| Polygon::new(p, fill)))
            .map_err(err)?;
        if !band.label.is_empty() {
            labelled = true;
            anno.label(band.label.as_str())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], fill));
        }
    }

    for (i, s) in panel.series.iter().enumerate() {
        let c = s.colour.map_or(color(i), |(r, g, b)| RGBColor(r, g, b));
        // thick lines through many sharp turns grow miter spikes: thin
        // lines once there are more points than half the pixel columns
        let dense = 2 * s.x.len() > grid.width;
        let line = c.stroke_width(if dense { 1 } else { 2 });
        let label = s.label.as_str();
        labelled |= !label.is_empty();
        match s.style {
            SeriesStyle::Points => {
                let dot = c.filled();
                let pts = thin_points(&s.x, &s.y, &grid);
                let anno = chart
                    .draw_series(pts.into_iter().map(|p| Circle::new(p, MARKER_RADIUS, dot)))
                    .map_err(err)?;
                if !label.is_empty() {
                    anno.label(label)
                        .legend(move |(x, y)| Circle::new((x + 10, y), 3, dot));
                }
            }
            SeriesStyle::Line | SeriesStyle::DashedLine => {
                draw_line_series(&mut chart, s, c, line, &grid)?;
            }
        }
    }

    if labelled && (panel.series.len() > 1 || panel.band.is_some()) {
        legend_box(&mut chart)?;
    }
    Ok(())
}

/// A linear axis 0..n whose ticks are exactly the given points (the
/// centres of categories or matrix cells), labelled by a formatter.
struct Slots {
    inner: RangedCoordf64,
    keys: Vec<f64>,
}

impl Slots {
    fn new(n: f64, keys: Vec<f64>) -> Self {
        Slots {
            inner: (0.0..n).into(),
            keys,
        }
    }
}

impl Ranged for Slots {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }
    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.keys.clone()
        }
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.inner.range()
    }
}

/// Tick label for `v` on an axis spanning `range`: no float noise, no "-0",
/// scientific notation for very large or very small magnitudes.
fn tick_label(v: f64, range: (f64, f64)) -> String {
    let step = (range.1 - range.0).abs() / 10.0;
    if !v.is_finite() || step.is_nan() || step <= 0.0 {
        return format!("{v}");
    }
    if v.abs() <= step * 1e-6 {
        return "0".to_string();
    }
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    let mag = range.0.abs().max(range.1.abs());
    if !(1e-3..1e5).contains(&mag) {
        let digits = ((mag / step).log10().ceil() as i32).clamp(1, 8) as usize;
        let s = format!("{v:.digits$e}");
        return match s.split_once('e') {
            Some((m, e)) => format!("{}e{e}", trim(m)),
            None => s,
        };
    }
    let decimals = ((-step.log10()).ceil() as i32 + 1).clamp(0, 12) as usize;
    let s = trim(&format!("{v:.decimals$}"));
    if s == "-0" {
        "0".to_string()
    } else {
        s
    }
}

fn category_label(labels: &[String], v: f64) -> String {
    let i = v.floor();
    if i >= 0.0 && (i as usize) < labels.len() {
        labels[i as usize].clone()
    } else {
        String::new()
    }
}

fn draw_bars<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    categories: &[String],
    groups: &[(String, Vec<f64>)],
) -> Draw {
    let nc = categories.len().max(1);
    let mut ey = Extent::new();
    ey.add(0.0);
    for (_, v) in groups {
        for &y in v {
            ey.add(y);
        }
    }
    let yr = ey.range(0.06);
    let centres: Vec<f64> = (0..categories.len()).map(|i| i as f64 + 0.5).collect();

    let mut builder = ChartBuilder::on(area);
    builder
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(66);
    if !panel.title.is_empty() {
        builder.caption(&panel.title, font(PANEL_TITLE_SIZE));
    }
    let mut chart = builder
        .build_cartesian_2d(Slots::new(nc as f64, centres), yr.0..yr.1)
        .map_err(err)?;
    let fmt = |v: &f64| category_label(categories, *v);
    let fy = |v: &f64| tick_label(*v, yr);
    let tick = if categories.len() > 16 {
        TICK_SIZE - 2.0
    } else {
        TICK_SIZE
    };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_label_formatter(&fmt)
        .y_label_formatter(&fy)
        .x_label_style(font(tick))
        .y_label_style(font(TICK_SIZE))
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .axis_desc_style(font(AXIS_DESC_SIZE))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(242, 242, 242))
        .max_light_lines(LIGHT_LINES)
        .draw()
        .map_err(err)?;

    let ng = groups.len().max(1) as f64;
    let slot = 0.8 / ng;
    let gap = slot * 0.08;
    for (g, (name, values)) in groups.iter().enumerate() {
        let fill = color(g).filled();
        let bars = values
            .iter()
            .enumerate()
            .filter(|(_, v)| ok(**v))
            .map(|(i, &v)| {
                let x0 = i as f64 + 0.1 + g as f64 * slot + gap;
                let x1 = i as f64 + 0.1 + (g + 1) as f64 * slot - gap;
                Rectangle::new([(x0, 0.0), (x1, v)], fill)
            });
        let anno = chart.draw_series(bars).map_err(err)?;
        if !name.is_empty() {
            anno.label(name.as_str())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], fill));
        }
    }
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(0.0, 0.0), (nc as f64, 0.0)],
            BLACK.stroke_width(1),
        )))
        .map_err(err)?;
    if groups.len() > 1 && groups.iter().any(|(n, _)| !n.is_empty()) {
        legend_box(&mut chart)?;
    }
    Ok(())
}

fn draw_matrix<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    values: &[Vec<f64>],
    row_labels: &[String],
    col_labels: &[String],
) -> Draw {
    let nr = values.len();
    let nc = values.first().map_or(0, Vec::len);
    let names = |given: &[String], n: usize| -> Vec<String> {
        if given.len() == n {
            given.to_vec()
        } else {
            (1..=n).map(|i| i.to_string()).collect()
        }
    };
    let rows = names(row_labels, nr);
    let cols = names(col_labels, nc);
    let (w, h) = (nc.max(1) as f64, nr.max(1) as f64);
    // Row i occupies y in [h-1-i, h-i] so that row 0 is at the top.
    let xk: Vec<f64> = (0..nc).map(|j| j as f64 + 0.5).collect();
    let yk: Vec<f64> = (0..nr).map(|i| h - 0.5 - i as f64).collect();

    let mut builder = ChartBuilder::on(area);
    builder
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(66);
    if !panel.title.is_empty() {
        builder.caption(&panel.title, font(PANEL_TITLE_SIZE));
    }
    let mut chart = builder
        .build_cartesian_2d(Slots::new(w, xk), Slots::new(h, yk))
        .map_err(err)?;
    let fx = |v: &f64| category_label(&cols, *v);
    let fy = |v: &f64| {
        let i = (h - v).floor();
        if i >= 0.0 && (i as usize) < rows.len() {
            rows[i as usize].clone()
        } else {
            String::new()
        }
    };
    chart
        .configure_mesh()
        .disable_mesh()
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .label_style(font(TICK_SIZE))
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .axis_desc_style(font(AXIS_DESC_SIZE))
        .draw()
        .map_err(err)?;

    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    let cell = (pw as f64 / w).min(ph as f64 / h);
    let text_size = (cell * 0.3).clamp(0.0, 14.0);
    let shade = |v: f64| -> RGBColor {
        if !v.is_finite() {
            return RGBColor(200, 200, 200);
        }
        let t = v.clamp(0.0, 1.0);
        let mix = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * t).round() as u8;
        RGBColor(mix(255, 8), mix(255, 48), mix(255, 107))
    };
    let cells = values.iter().enumerate().flat_map(|(i, row)| {
        row.iter().enumerate().map(move |(j, &v)| {
            let y = h - 1.0 - i as f64;
            Rectangle::new(
                [(j as f64, y), (j as f64 + 1.0, y + 1.0)],
                shade(v).filled(),
            )
        })
    });
    chart.draw_series(cells).map_err(err)?;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(0.0, 0.0), (w, h)],
            RGBColor(120, 120, 120).stroke_width(1),
        )))
        .map_err(err)?;
    if text_size >= 7.0 {
        let texts = values.iter().enumerate().flat_map(|(i, row)| {
            row.iter().enumerate().map(move |(j, &v)| {
                let s = if v.is_finite() {
                    format!("{v:.2}")
                } else {
                    "–".to_string()
                };
                let ink: &'static RGBColor = if v.is_finite() && v > 0.55 {
                    &WHITE
                } else {
                    &BLACK
                };
                let style = TextStyle::from((FAMILY, text_size).into_font())
                    .color(ink)
                    .pos(Pos::new(HPos::Center, VPos::Center));
                Text::new(s, (j as f64 + 0.5, h - 0.5 - i as f64), style)
            })
        });
        chart.draw_series(texts).map_err(err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Copy outputs to `$TACIT_PLOT_KEEP/<name>.{png,svg}` for a visual check.
    fn keep(paths: &[PathBuf], name: &str) {
        if let Some(dir) = std::env::var_os("TACIT_PLOT_KEEP") {
            for p in paths {
                let ext = p.extension().unwrap().to_str().unwrap();
                std::fs::copy(p, Path::new(&dir).join(format!("{name}.{ext}"))).unwrap();
            }
        }
    }

    fn demo_figure() -> Figure {
        let t: Vec<f64> = (0..500).map(|i| i as f64 * 0.01).collect();
        let a: Vec<f64> = t.iter().map(|t| (6.0 * t).sin()).collect();
        let b: Vec<f64> = t.iter().map(|t| 0.8 * (6.0 * t).sin() + 0.1).collect();
        let sig: Vec<f64> = t.iter().map(|t| 0.1 + 0.02 * t).collect();
        let lines = time_panel(
            "displacement",
            "x [m]",
            &t,
            vec![
                ("test".into(), a.clone(), SeriesStyle::Line),
                ("model".into(), b.clone(), SeriesStyle::DashedLine),
            ],
        )
        .with_band(Band::around(
            "±2σ",
            &t,
            &b,
            &sig.iter().map(|s| 2.0 * s).collect::<Vec<_>>(),
        ));
        let pts = Panel::xy(
            "restoring force",
            "x [m]",
            "f [N]",
            vec![
                Series::points("measured", a.clone(), b.iter().map(|v| v * v * v).collect()),
                Series::line("fit", vec![-1.0, 1.0], vec![-0.5, 0.5]),
                Series::line("empty", vec![], vec![]),
            ],
        );
        let springs: Vec<String> = (1..=5).map(|i| format!("k{i}")).collect();
        let bars = Panel::bars(
            "adjustment",
            "spring",
            "change [%]",
            springs,
            vec![
                ("direct".into(), vec![1.0, -4.0, 12.5, 0.0, f64::NAN]),
                ("sensitivity".into(), vec![2.0, -3.0, 10.0, 0.5, 1.0]),
                ("Bayes".into(), vec![1.5, -3.5, 11.0, 0.2, 0.8]),
            ],
        );
        let mac = Panel::matrix(
            "MAC",
            "model mode",
            "test mode",
            vec![
                vec![0.99, 0.02, 0.10],
                vec![0.01, 0.95, 0.30],
                vec![0.05, 0.40, f64::NAN],
            ],
            vec!["T1".into(), "T2".into(), "T3".into()],
            vec![],
        );
        Figure::new("demo", vec![lines, pts, bars, mac], 2)
    }

    #[test]
    fn plot_grid_png_and_svg() {
        let dir = tempfile::tempdir().unwrap();
        let fig = demo_figure();
        let start = std::time::Instant::now();
        let paths = save(&fig, &dir.path().join("demo")).unwrap();
        eprintln!(
            "2x2 {}x{} PNG+SVG: {:?}",
            fig.width,
            fig.height,
            start.elapsed()
        );
        keep(&paths, "demo");
        assert_eq!(paths.len(), 2);
        let png = std::fs::read(&paths[0]).unwrap();
        assert!(paths[0].ends_with("demo.png"));
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        let svg = std::fs::read_to_string(&paths[1]).unwrap();
        assert!(paths[1].ends_with("demo.svg"));
        assert!(svg.contains("<svg"));
        assert!(svg.contains("MAC") && svg.contains("0.99") && svg.contains("sensitivity"));
        // Only the two outputs remain: temporary files are gone.
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 2, "{names:?}");
    }

    #[test]
    fn plot_single_panel_timing() {
        let dir = tempfile::tempdir().unwrap();
        let t: Vec<f64> = (0..2000).map(|i| i as f64 * 1e-3).collect();
        let y: Vec<f64> = t.iter().map(|t| (30.0 * t).sin()).collect();
        let fig = Figure::single(
            "one",
            time_panel("", "y", &t, vec![("y".into(), y, SeriesStyle::Line)]),
        );
        assert_eq!((fig.width, fig.height), (800, 540));
        save(&fig, &dir.path().join("warm")).unwrap();
        let start = std::time::Instant::now();
        save(&fig, &dir.path().join("one")).unwrap();
        eprintln!("800x540 PNG+SVG: {:?}", start.elapsed());
    }

    #[test]
    fn plot_huge_series_is_decimated() {
        let dir = tempfile::tempdir().unwrap();
        let n = 200_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-4).collect();
        let noisy: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 1000) as f64 / 1000.0 + (i as f64 * 1e-3).sin())
            .collect();
        let smooth: Vec<f64> = t.iter().map(|t| (2.0 * t).cos()).collect();
        let band = Band::around("±2σ", &t, &smooth, &vec![0.2; n]);
        let fig = Figure::single(
            "huge",
            time_panel(
                "200k points",
                "y",
                &t,
                vec![
                    ("noisy".into(), noisy.clone(), SeriesStyle::Line),
                    ("smooth".into(), smooth, SeriesStyle::DashedLine),
                    (
                        "dashed noise".into(),
                        noisy.clone(),
                        SeriesStyle::DashedLine,
                    ),
                    ("points".into(), noisy, SeriesStyle::Points),
                ],
            )
            .with_band(band),
        );
        let start = std::time::Instant::now();
        let paths = save(&fig, &dir.path().join("huge")).unwrap();
        eprintln!("200k x 4 series: {:?}", start.elapsed());
        let svg = std::fs::metadata(&paths[1]).unwrap().len();
        keep(&paths, "huge");
        let png = std::fs::metadata(&paths[0]).unwrap().len();
        eprintln!("svg {svg} bytes, png {png} bytes");
        assert!(svg < 2_000_000, "SVG is {svg} bytes");
    }

    #[test]
    fn plot_nan_and_degenerate_data() {
        let dir = tempfile::tempdir().unwrap();
        let nan = f64::NAN;
        let panels = vec![
            Panel::xy(
                "nan",
                "x",
                "y",
                vec![
                    Series::line(
                        "a",
                        vec![0.0, 1.0, nan, 3.0, 4.0],
                        vec![1.0, nan, 2.0, 3.0, f64::INFINITY],
                    ),
                    Series::points("b", vec![nan, nan], vec![nan, nan]),
                    Series::dashed("c", vec![0.0, 1.0, 2.0], vec![5.0, 5.0, 5.0]),
                ],
            )
            .with_band(Band::new(
                "band",
                vec![0.0, 1.0, 2.0],
                vec![nan, 0.0, 1.0],
                vec![1.0, nan, 2.0],
            )),
            Panel::xy(
                "all NaN",
                "x",
                "y",
                vec![Series::line("z", vec![nan; 3], vec![nan; 3])],
            ),
            Panel::xy("empty", "x", "y", vec![]),
            Panel::xy(
                "constant",
                "x",
                "y",
                vec![Series::line("k", vec![2.0, 2.0], vec![0.0, 0.0])],
            ),
            Panel::xy(
                "huge values",
                "x",
                "y",
                vec![Series::line(
                    "h",
                    vec![0.0, 1.0, 2.0],
                    vec![-1e308, 1e308, 1.0],
                )],
            ),
            Panel::bars(
                "bars",
                "",
                "%",
                vec!["a".into(), "b".into()],
                vec![("m".into(), vec![nan, nan])],
            ),
            Panel::bars("no bars", "", "%", vec![], vec![]),
            Panel::matrix("empty matrix", "", "", vec![], vec![], vec![]),
        ];
        let fig = Figure::new("", panels, 3);
        let paths = save(&fig, &dir.path().join("nan")).unwrap();
        keep(&paths, "nan");
        assert!(paths.iter().all(|p| p.is_file()));
        assert!(save(
            &Figure::new("no panels", vec![], 1),
            &dir.path().join("none")
        )
        .is_ok());
    }

    #[test]
    fn plot_rejects_inconsistent_data() {
        let dir = tempfile::tempdir().unwrap();
        let fig = Figure::single(
            "bad",
            Panel::xy(
                "p",
                "x",
                "y",
                vec![Series::line("s", vec![1.0, 2.0], vec![1.0])],
            ),
        );
        let e = save(&fig, &dir.path().join("bad")).unwrap_err().to_string();
        assert!(e.contains("series 's'"), "{e}");
        let mut small = Figure::single("small", Panel::default());
        small.width = 50;
        assert!(save(&small, &dir.path().join("small")).is_err());
        let missing = dir.path().join("no/such/dir/fig");
        assert!(save(&Figure::single("x", Panel::default()), &missing).is_err());
    }

    #[test]
    fn plot_tick_labels() {
        assert_eq!(tick_label(0.5, (0.0, 5.0)), "0.5");
        assert_eq!(tick_label(2.0, (0.0, 5.0)), "2");
        assert_eq!(tick_label(-1e-17, (-1.0, 1.0)), "0");
        assert_eq!(tick_label(0.30000000000000004, (0.0, 1.0)), "0.3");
        assert_eq!(tick_label(0.25, (0.0, 1.0)), "0.25");
        assert_eq!(tick_label(150000.0, (0.0, 200000.0)), "1.5e5");
        assert_eq!(tick_label(-5e-5, (-1e-4, 1e-4)), "-5e-5");
        assert_eq!(tick_label(12.0, (-4.0, 13.0)), "12");
    }

    #[test]
    fn plot_decimation_keeps_extremes() {
        let grid = PixelGrid::new((0.0, 1.0), (-1.0, 1.0), (10, 100));
        let run: Vec<(f64, f64)> = (0..1000)
            .map(|i| {
                (
                    i as f64 / 1000.0,
                    if i == 537 {
                        -0.9
                    } else if i == 538 {
                        0.95
                    } else {
                        0.0
                    },
                )
            })
            .collect();
        let d = decimate(run, &grid);
        assert!(d.len() <= 40, "{}", d.len());
        assert!(d.contains(&(0.537, -0.9)) && d.contains(&(0.538, 0.95)));
        assert_eq!(d.first().unwrap().0, 0.0);
        assert_eq!(d.last().unwrap().0, 0.999);
        assert!(d.windows(2).all(|w| w[0].0 <= w[1].0));
    }
}

//! The report's figures (the paper's Figs. 7–14): ZMP with the support bounds, hand tracking
//! error, CoM, K_p and the hand force, each controller overlaid. Every figure is written as SVG
//! and, when the font can be loaded, as PNG, from any [`SeriesSource`].

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
// BackendStyle stays qualified: in scope it would clash with `Color::stroke_width`.
use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingErrorKind};

use super::ReportError;
use super::series::{Quantity, SeriesSource};

/// The font the PNGs are drawn with (Debian package fonts-dejavu-core); `UPC_REPORT_FONT`
/// overrides the path.
pub const DEFAULT_FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
const FONT_FAMILY: &str = "sans-serif";

/// Load and register the font once per process. `false` (with one warning) if it cannot be.
pub fn font_available() -> bool {
    static LOADED: OnceLock<bool> = OnceLock::new();
    *LOADED.get_or_init(|| {
        let path = std::env::var_os("UPC_REPORT_FONT")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(DEFAULT_FONT));
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) => {
                tracing::warn!(
                    "font {} cannot be read ({e}): writing SVG figures only, no PNG \
                     (install fonts-dejavu-core, or run scripts/setup.sh)",
                    path.display()
                );
                return false;
            }
        };
        // plotters keeps fonts for the life of the process: leak the one buffer, once.
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        match plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, bytes) {
            Ok(()) => true,
            Err(_) => {
                tracing::warn!(
                    "{} is not a usable font: writing SVG figures only, no PNG",
                    path.display()
                );
                false
            }
        }
    })
}

/// One plotted line of a panel.
#[derive(Debug, Clone, Copy)]
pub enum Line {
    /// One line per source, coloured by controller.
    PerSource(Quantity),
    /// A signal common to all sources (reference, forecast): drawn once, from the first source
    /// that has it, with its own label.
    Common(Quantity, &'static str),
}

#[derive(Debug, Clone)]
pub struct Panel {
    pub title: &'static str,
    pub y_label: &'static str,
    /// Values are multiplied by this before plotting (e.g. 1e3 for mm).
    pub scale: f64,
    pub lines: Vec<Line>,
    /// Draw the support bounds of this axis (0: x, 1: y).
    pub support_axis: Option<usize>,
}

#[derive(Debug, Clone)]
pub struct Figure {
    /// File stem under `figures/`.
    pub name: String,
    pub title: String,
    /// What the sources' "time" axis holds (most figures: "t (s)").
    pub x_label: &'static str,
    pub panels: Vec<Panel>,
}

/// The figure set of one section (one scenario's full-simulation or reduced-model runs).
pub fn standard_figures(prefix: &str, what: &str) -> Vec<Figure> {
    let fig = |name: &str, title: &str, panels| Figure {
        name: format!("{prefix}_{name}"),
        title: format!("{title} — {what}"),
        x_label: "t (s)",
        panels,
    };
    vec![
        fig("zmp", "ZMP and support bounds", zmp_panels()),
        fig(
            "zmp_pred",
            "Preview-model ZMP one step ahead",
            zmp_pred_panels(),
        ),
        fig(
            "hand_error",
            "Hand tracking error",
            vec![panel(
                "hand error",
                "error (mm)",
                1e3,
                vec![Line::PerSource(Quantity::HandError)],
                None,
            )],
        ),
        fig("com", "CoM position", com_panels()),
        fig(
            "kp",
            "Hand stiffness K_p",
            vec![panel(
                "K_p",
                "K_p (1/s²)",
                1.0,
                vec![Line::PerSource(Quantity::Kp)],
                None,
            )],
        ),
        fig(
            "force",
            "Hand force forecast and CoM disturbance",
            force_panels(),
        ),
    ]
}

fn panel(
    title: &'static str,
    y_label: &'static str,
    scale: f64,
    lines: Vec<Line>,
    support_axis: Option<usize>,
) -> Panel {
    Panel {
        title,
        y_label,
        scale,
        lines,
        support_axis,
    }
}

/// The ZMP along x and y, its reference and the support bounds.
fn zmp_panels() -> Vec<Panel> {
    use Quantity::*;
    vec![
        panel(
            "ZMP x",
            "x (m)",
            1.0,
            vec![Line::Common(ZmpRefX, "reference"), Line::PerSource(ZmpX)],
            Some(0),
        ),
        panel(
            "ZMP y",
            "y (m)",
            1.0,
            vec![Line::Common(ZmpRefY, "reference"), Line::PerSource(ZmpY)],
            Some(1),
        ),
    ]
}

/// The ZMP the preview predicts one step ahead, and the support bounds.
fn zmp_pred_panels() -> Vec<Panel> {
    use Quantity::*;
    vec![
        panel(
            "predicted ZMP x",
            "x (m)",
            1.0,
            vec![Line::PerSource(ZmpPredX)],
            Some(0),
        ),
        panel(
            "predicted ZMP y",
            "y (m)",
            1.0,
            vec![Line::PerSource(ZmpPredY)],
            Some(1),
        ),
    ]
}

/// The CoM along x, y and z.
fn com_panels() -> Vec<Panel> {
    use Quantity::*;
    vec![
        panel("CoM x", "x (m)", 1.0, vec![Line::PerSource(ComX)], None),
        panel("CoM y", "y (m)", 1.0, vec![Line::PerSource(ComY)], None),
        panel("CoM z", "z (m)", 1.0, vec![Line::PerSource(ComZ)], None),
    ]
}

/// The hand force forecast (common to all controllers) and each one's CoM disturbance.
fn force_panels() -> Vec<Panel> {
    use Quantity::*;
    vec![
        panel(
            "hand force forecast F_ext",
            "force (N)",
            1.0,
            vec![
                Line::Common(FExtX, "F_ext x"),
                Line::Common(FExtY, "F_ext y"),
                Line::Common(FExtZ, "F_ext z"),
            ],
            None,
        ),
        panel(
            "CoM disturbance F_dis x",
            "force (N)",
            1.0,
            vec![Line::PerSource(FDisX)],
            None,
        ),
    ]
}

/// A figure as written: its file names relative to the report and its title.
#[derive(Debug, Clone)]
pub struct Written {
    pub title: String,
    pub svg: String,
    pub png: Option<String>,
}

/// A line ready to draw: label, colour, dashed, points.
struct Trace {
    label: String,
    color: RGBColor,
    dashed: bool,
    width: u32,
    points: Vec<(f64, f64)>,
}

const WIDTH: u32 = 1000;
const PANEL_HEIGHT: u32 = 280;
const TITLE_HEIGHT: u32 = 36;

/// Colour of a controller's line, the same in every figure.
pub fn color_of(label: &str, index: usize) -> RGBColor {
    match label.to_ascii_lowercase().as_str() {
        "c0" => RGBColor(214, 39, 40),
        "c1" => RGBColor(31, 119, 180),
        "c2" => RGBColor(44, 160, 44),
        _ => [
            RGBColor(148, 103, 189),
            RGBColor(255, 127, 14),
            RGBColor(140, 86, 75),
            RGBColor(227, 119, 194),
            RGBColor(23, 190, 207),
            RGBColor(188, 189, 34),
            RGBColor(127, 127, 127),
            RGBColor(31, 119, 180),
        ][index % 8],
    }
}

fn panel_traces(panel: &Panel, sources: &[&dyn SeriesSource]) -> Vec<Trace> {
    let points = |s: &dyn SeriesSource, q: Quantity| -> Option<Vec<(f64, f64)>> {
        let v = s.values(q)?;
        Some(
            s.time()
                .iter()
                .zip(v)
                .filter(|(t, y)| t.is_finite() && y.is_finite())
                .map(|(t, y)| (*t, y * panel.scale))
                .collect(),
        )
    };
    let mut traces = Vec::new();
    let grays = [
        RGBColor(110, 110, 110),
        RGBColor(160, 160, 160),
        RGBColor(60, 60, 60),
    ];
    let mut common = 0;
    for line in &panel.lines {
        match *line {
            Line::PerSource(q) => {
                for (i, s) in sources.iter().enumerate() {
                    if let Some(p) = points(*s, q) {
                        traces.push(Trace {
                            label: s.label().to_string(),
                            color: color_of(s.label(), i),
                            dashed: false,
                            width: 2,
                            points: p,
                        });
                    }
                }
            }
            Line::Common(q, label) => {
                if let Some(p) = sources.iter().find_map(|s| points(*s, q)) {
                    // Several common lines in one panel (F_ext x/y/z) need distinct colours.
                    let color = if panel.lines.len() > 1
                        && panel.lines.iter().all(|l| matches!(l, Line::Common(..)))
                    {
                        [RGBColor(31, 119, 180), RGBColor(255, 127, 14), grays[2]][common % 3]
                    } else {
                        grays[common % 3]
                    };
                    common += 1;
                    traces.push(Trace {
                        label: label.to_string(),
                        color,
                        dashed: false,
                        width: 1,
                        points: p,
                    });
                }
            }
        }
    }
    if traces.is_empty() {
        return traces;
    }
    if let Some(axis) = panel.support_axis
        && let Some(sup) = sources.iter().find_map(|s| s.support())
    {
        let (t0, t1) = time_range(sources);
        for (k, bound) in sup[axis].iter().enumerate() {
            if bound.is_finite() {
                traces.push(Trace {
                    label: if k == 0 {
                        "support".into()
                    } else {
                        String::new()
                    },
                    color: BLACK,
                    dashed: true,
                    width: 1,
                    points: vec![(t0, bound * panel.scale), (t1, bound * panel.scale)],
                });
            }
        }
    }
    traces
}

/// The support bounds drawn in a panel (its dashed traces), low and high.
fn support_bounds(traces: &[Trace]) -> Option<[f64; 2]> {
    let b: Vec<f64> = traces
        .iter()
        .filter(|t| t.dashed)
        .filter_map(|t| t.points.first().map(|p| p.1))
        .collect();
    match b[..] {
        [lo, hi] if hi > lo => Some([lo, hi]),
        _ => None,
    }
}

fn time_range(sources: &[&dyn SeriesSource]) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in sources {
        for t in s.time().iter().filter(|t| t.is_finite()) {
            lo = lo.min(*t);
            hi = hi.max(*t);
        }
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        hi = lo + 1.0;
    }
    (lo, hi)
}

fn value_range(traces: &[Trace]) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for p in traces.iter().flat_map(|t| &t.points) {
        lo = lo.min(p.1);
        hi = hi.max(p.1);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    let pad = if span > 1e-12 {
        0.06 * span
    } else {
        1e-3_f64.max(lo.abs() * 0.05)
    };
    (lo - pad, hi + pad)
}

/// Write `fig` as `<dir>/<name>.svg` (and `.png` if the font is loaded). `None` if no source
/// has any of its quantities.
pub fn write_figure(
    dir: &Path,
    fig: &Figure,
    sources: &[&dyn SeriesSource],
    png: bool,
) -> Result<Option<Written>, ReportError> {
    let panels: Vec<(&Panel, Vec<Trace>)> = fig
        .panels
        .iter()
        .map(|p| (p, panel_traces(p, sources)))
        .filter(|(_, t)| !t.is_empty())
        .collect();
    if panels.is_empty() {
        return Ok(None);
    }
    let size = (WIDTH, TITLE_HEIGHT + PANEL_HEIGHT * panels.len() as u32);
    let x_range = time_range(sources);
    let svg_name = format!("{}.svg", fig.name);
    let svg_path = dir.join(&svg_name);
    let plot_err = |path: &Path, e: String| ReportError::Plot {
        path: path.to_path_buf(),
        message: e,
    };
    {
        let root = SvgText(SVGBackend::new(&svg_path, size)).into_drawing_area();
        draw(&root, fig, &panels, x_range).map_err(|e| plot_err(&svg_path, e))?;
        root.present()
            .map_err(|e| plot_err(&svg_path, e.to_string()))?;
    }
    let png_name = if png && font_available() {
        let name = format!("{}.png", fig.name);
        let path = dir.join(&name);
        let root = BitMapBackend::new(&path, size).into_drawing_area();
        draw(&root, fig, &panels, x_range).map_err(|e| plot_err(&path, e))?;
        root.present().map_err(|e| plot_err(&path, e.to_string()))?;
        Some(name)
    } else {
        None
    };
    Ok(Some(Written {
        title: fig.title.clone(),
        svg: svg_name,
        png: png_name,
    }))
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
    panels: &[(&Panel, Vec<Trace>)],
    x_range: (f64, f64),
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let (top, rest) = root.split_vertically(TITLE_HEIGHT);
    top.draw(&Text::new(
        fig.title.clone(),
        (12, TITLE_HEIGHT as i32 / 2),
        (FONT_FAMILY, 18)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Left, VPos::Center)),
    ))
    .map_err(e)?;
    let areas = rest.split_evenly((panels.len(), 1));
    for (area, (panel, traces)) in areas.iter().zip(panels) {
        draw_panel(area, fig.x_label, panel, traces, x_range)?;
    }
    Ok(())
}

/// One panel: its axes, its traces, and above them its title and legend.
fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x_label: &str,
    panel: &Panel,
    traces: &[Trace],
    x_range: (f64, f64),
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (y0, y1, cut) = y_range(traces);
    let legend = Legend::lay_out(traces, area.dim_in_pixel().0 as i32 - 24, panel.title);
    let mut chart = ChartBuilder::on(area)
        .margin(8)
        .margin_top(26 + 16 * legend.lines.len() as u32)
        .x_label_area_size(34)
        .y_label_area_size(72)
        .build_cartesian_2d(x_range.0..x_range.1, y0..y1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(panel.y_label)
        .label_style((FONT_FAMILY, 12))
        .axis_desc_style((FONT_FAMILY, 13))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()
        .map_err(e)?;
    for t in traces {
        let style = t.color.stroke_width(t.width);
        let points = t.points.iter().map(|&(x, y)| (x, y.clamp(y0, y1)));
        if t.dashed {
            chart
                .draw_series(DashedLineSeries::new(points, 6, 4, style))
                .map_err(e)?;
        } else {
            chart
                .draw_series(LineSeries::new(points, style))
                .map_err(e)?;
        }
    }
    let title = if cut.is_empty() {
        panel.title.to_string()
    } else {
        format!(
            "{} (axis cut at 1.5 support widths; {} beyond, drawn on the edge)",
            panel.title,
            cut.join(", ")
        )
    };
    legend.draw(area, &title)
}

/// The panel's value axis, and the traces drawn cut at its edges. A run that falls sends the
/// ZMP metres away: keep the axis on the support (1.5 of its widths either side), draw what
/// lies beyond on the axis edge and say whose it is.
fn y_range(traces: &[Trace]) -> (f64, f64, Vec<&str>) {
    let (mut y0, mut y1) = value_range(traces);
    let mut cut: Vec<&str> = Vec::new();
    if let Some([lo, hi]) = support_bounds(traces) {
        let (a, b) = (lo - 1.5 * (hi - lo), hi + 1.5 * (hi - lo));
        if y0 < a || y1 > b {
            for t in traces.iter().filter(|t| !t.dashed) {
                if t.points.iter().any(|p| p.1 < a || p.1 > b) && !cut.contains(&&*t.label) {
                    cut.push(&t.label);
                }
            }
            (y0, y1) = (y0.max(a), y1.min(b));
        }
    }
    (y0, y1, cut)
}

/// A panel's legend: one line beside the title when it fits, else lines of its own below it
/// (right-aligned), the plot moved down to make room.
struct Legend<'a> {
    /// The labelled traces.
    entries: Vec<&'a Trace>,
    /// Each entry's width (px).
    widths: Vec<i32>,
    /// The entries of each line of their own (none: beside the title).
    lines: Vec<Vec<usize>>,
    /// The width the legend may take (px).
    full: i32,
}

impl<'a> Legend<'a> {
    fn lay_out(traces: &'a [Trace], full: i32, title: &str) -> Legend<'a> {
        let entries: Vec<&Trace> = traces.iter().filter(|t| !t.label.is_empty()).collect();
        let widths: Vec<i32> = entries
            .iter()
            .map(|t| 30 + 8 * t.label.chars().count() as i32 + 14)
            .collect();
        let beside = widths.iter().sum::<i32>() + 80 + 8 * title.chars().count() as i32;
        let mut lines: Vec<Vec<usize>> = Vec::new();
        if beside > full {
            let mut used = full;
            for (i, w) in widths.iter().enumerate() {
                if used + w > full {
                    lines.push(Vec::new());
                    used = 0;
                }
                used += w;
                if let Some(l) = lines.last_mut() {
                    l.push(i);
                }
            }
        }
        Legend {
            entries,
            widths,
            lines,
            full,
        }
    }

    /// The panel's title and the legend in the strip above the plot, drawn as plain text:
    /// plotters' own legend measures text with the font, which the SVG must not need.
    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        title: &str,
    ) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        let text = |s: &str, x: i32, y: i32, color: &RGBColor| {
            Text::new(
                s.to_string(),
                (x, y),
                (FONT_FAMILY, 13)
                    .into_font()
                    .color(color)
                    .pos(Pos::new(HPos::Left, VPos::Center)),
            )
        };
        area.draw(&text(title, 80, 12, &BLACK)).map_err(e)?;
        let one_line = [(0..self.entries.len()).collect::<Vec<usize>>()];
        let rows: &[Vec<usize>] = if self.lines.is_empty() {
            &one_line
        } else {
            &self.lines
        };
        for (r, row) in rows.iter().enumerate() {
            let y = if self.lines.is_empty() {
                12
            } else {
                28 + 16 * r as i32
            };
            let mut x = self.full + 12 - row.iter().map(|&i| self.widths[i]).sum::<i32>();
            for &i in row {
                let t = self.entries[i];
                let style = t.color.stroke_width(2);
                if t.dashed {
                    area.draw(&PathElement::new(vec![(x, y), (x + 9, y)], style))
                        .map_err(e)?;
                    area.draw(&PathElement::new(vec![(x + 15, y), (x + 24, y)], style))
                        .map_err(e)?;
                } else {
                    area.draw(&PathElement::new(vec![(x, y), (x + 24, y)], style))
                        .map_err(e)?;
                }
                area.draw(&text(&t.label, x + 30, y, &BLACK)).map_err(e)?;
                x += self.widths[i];
            }
        }
        Ok(())
    }
}

/// The SVG backend, measuring text without a font when none is loaded: SVG text is laid out
/// by the viewer, so the estimate only places axis labels, and the SVGs never need the font.
struct SvgText<'a>(SVGBackend<'a>);

impl DrawingBackend for SvgText<'_> {
    type ErrorType = <SVGBackend<'static> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }
    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.ensure_prepared()
    }
    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.present()
    }
    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_pixel(point, color)
    }
    fn draw_line<S: plotters_backend::BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_line(from, to, style)
    }
    fn draw_rect<S: plotters_backend::BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_rect(upper_left, bottom_right, style, fill)
    }
    fn draw_path<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_path(path, style)
    }
    fn draw_circle<S: plotters_backend::BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_circle(center, radius, style, fill)
    }
    fn fill_polygon<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.fill_polygon(vert, style)
    }
    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_text(text, style, pos)
    }
    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> Result<(u32, u32), DrawingErrorKind<Self::ErrorType>> {
        match style.layout_box(text) {
            Ok(((x0, y0), (x1, y1))) => Ok(((x1 - x0) as u32, (y1 - y0) as u32)),
            Err(_) => {
                let size = style.size();
                Ok((
                    (0.6 * size * text.chars().count() as f64).ceil() as u32,
                    size.ceil() as u32,
                ))
            }
        }
    }
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        (iw, ih): (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.blit_bitmap(pos, (iw, ih), src)
    }
}

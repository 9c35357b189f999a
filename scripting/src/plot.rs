//! `granite plot`: line plots of series.csv columns as SVG or PNG, so energies, runout and stress
//! paths can be looked at without other tools.

use granite_core::error::{GraniteError, Result};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Reads a CSV with a header row into column names and numeric rows (non-numbers become NaN).
fn read_csv(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>)> {
    let text = std::fs::read_to_string(path).map_err(|e| GraniteError::io(path, e))?;
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap_or_default().split(',').map(|s| s.trim().to_string()).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.trim().parse::<f64>().unwrap_or(f64::NAN)).collect()).collect();
    Ok((header, rows))
}

/// One column of a CSV with a header row, by name (non-numbers as NaN).
pub fn read_column(csv: &Path, column: &str) -> Result<Vec<f64>> {
    let (header, rows) = read_csv(csv)?;
    let k = header.iter().position(|h| h == column).ok_or_else(|| GraniteError::Unknown {
        kind: format!("column of {}", csv.display()),
        name: column.into(),
        known: header.join(", "),
    })?;
    Ok(rows.iter().map(|r| r.get(k).copied().unwrap_or(f64::NAN)).collect())
}

/// The unit of an output column of granite's series files, for axis labels ("" for a count or a
/// ratio; None for a column granite does not write, e.g. a script's own).
pub fn unit_of(column: &str) -> Option<&'static str> {
    let c = column;
    Some(match c {
        "time" | "time_s" => "s",
        "step" | "points" | "deleted_points" | "particles" | "contacts" | "rattlers" | "spheres" => "count",
        "runout_normalised"
        | "time_normalised"
        | "coordination"
        | "void_ratio"
        | "porosity"
        | "unbalanced_force"
        | "axial_strain"
        | "volumetric_strain"
        | "max_deviatoric_strain"
        | "inertial_number" => "1",
        "max_height" | "max_x" | "lx" | "runout" | "x" | "y" | "z" => "m",
        "p" | "q" | "mean_stress" | "deviatoric_stress" => "Pa",
        _ if c.ends_with("_energy") || c.starts_with("energy_") || c == "boundary_work" => "J (2D MPM: J/m)",
        _ if c.starts_with("angular_momentum_") => "kg m^2/s (2D MPM: kg m/s)",
        _ if c.starts_with("momentum_") => "kg m/s (2D MPM: kg/s)",
        _ if c.starts_with("stress_") || c.starts_with("sigma_") || c.starts_with("q_") || c.starts_with("p_") => "Pa",
        _ => return None,
    })
}

/// "name [unit]" for an axis.
fn axis_label(names: &[&str], unit: Option<&str>) -> String {
    match unit {
        Some("count") | Some("1") | None => names.join(", "),
        Some(u) => format!("{} [{u}]", names.join(", ")),
    }
}

/// Plots `ys` against `x` from a CSV file into an SVG, or a PNG when `out` ends in `.png`;
/// returns the file written. Columns of
/// different units go to panels of their own, one above the other, each axis labelled with its
/// unit: one quantity per axis.
pub fn plot(csv: &Path, x: &str, ys: &[String], out: Option<PathBuf>) -> Result<PathBuf> {
    let (header, rows) = read_csv(csv)?;
    // A file that is not a series (a mistyped path) must not have its first line printed.
    let names_only = header.iter().all(|h| {
        (1..=64).contains(&h.len()) && h.chars().all(|c| c.is_ascii_alphanumeric() || "_-. ()[]/".contains(c))
    });
    let known = if names_only {
        header.join(", ")
    } else {
        "none: its first line is not a row of column names (is it a series file of granite?)".into()
    };
    let col = |name: &str| {
        header.iter().position(|h| h == name).ok_or_else(|| GraniteError::Unknown {
            kind: format!("column of {}", csv.display()),
            name: name.into(),
            known: known.clone(),
        })
    };
    let xi = col(x)?;
    let yi: Vec<usize> = ys.iter().map(|y| col(y)).collect::<Result<_>>()?;
    if yi.is_empty() {
        return Err(GraniteError::Setup("give at least one column to plot with --y".into()));
    }
    let xs: Vec<f64> = rows.iter().map(|r| r.get(xi).copied().unwrap_or(f64::NAN)).collect();
    // Panels: the columns grouped by unit, in the order given (columns of unknown unit apart).
    let mut panels: Vec<(Option<&str>, Vec<usize>)> = Vec::new();
    for (k, y) in ys.iter().enumerate() {
        let unit = unit_of(y);
        match panels.iter_mut().find(|(u, _)| unit.is_some() && *u == unit) {
            Some((_, members)) => members.push(k),
            None => panels.push((unit, vec![k])),
        }
    }
    let finite = |v: f64| v.is_finite();
    let mut ranges = Vec::with_capacity(panels.len());
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, members) in &panels {
        let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
        for (r, &xv) in rows.iter().zip(&xs) {
            for &k in members {
                let yv = r.get(yi[k]).copied().unwrap_or(f64::NAN);
                if finite(xv) && finite(yv) {
                    x0 = x0.min(xv);
                    x1 = x1.max(xv);
                    y0 = y0.min(yv);
                    y1 = y1.max(yv);
                }
            }
        }
        if !y0.is_finite() {
            let names: Vec<&str> = members.iter().map(|&k| ys[k].as_str()).collect();
            return Err(GraniteError::Setup(format!("no finite values of {} in {}", names.join(", "), csv.display())));
        }
        if y1 <= y0 {
            y1 = y0 + y0.abs().max(1.0) * 1e-3;
        }
        let pad = 0.05 * (y1 - y0);
        ranges.push((y0 - pad, y1 + pad));
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let out = out.unwrap_or_else(|| csv.with_file_name(format!("plot_{}.svg", ys.join("_"))));
    let png = is_png("plot", &out)?;
    let height = 120 + 380 * panels.len() as u32;
    let figure = Figure { x, ys, xs: &xs, rows: &rows, yi: &yi, panels: &panels, ranges: &ranges, x_range: (x0, x1) };
    render("plot", &figure, &out, png, (900, height))?;
    Ok(out)
}

/// Whether `out` names a PNG (else an SVG; no extension: SVG); another extension is refused.
fn is_png(call: &str, out: &Path) -> Result<bool> {
    match out.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("png") => Ok(true),
        Some("svg") | None => Ok(false),
        Some(other) => Err(GraniteError::Setup(format!(
            "{call} {}: `.{other}` is not an image format granite writes; name the file .svg or .png",
            out.display()
        ))),
    }
}

/// A picture that draws itself on any backend; `scale` multiplies sizes (text, margins, lines)
/// for a bitmap drawn larger than the SVG.
trait Picture {
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
        scale: u32,
    ) -> std::result::Result<(), String>;
}

/// Draws `picture` into `out`: an SVG of `size`, or a PNG twice as large in pixels (lines and
/// labels stay sharp on a screen).
fn render(call: &str, picture: &impl Picture, out: &Path, png: bool, (width, height): (u32, u32)) -> Result<()> {
    let err = |e: String| GraniteError::Other(format!("{call} {}: {e}", out.display()));
    // Text is measured with the embedded font for either format.
    embedded_font()?;
    if png {
        picture.draw(BitMapBackend::new(out, (2 * width, 2 * height)).into_drawing_area(), 2).map_err(err)
    } else {
        picture.draw(SVGBackend::new(out, (width, height)).into_drawing_area(), 1).map_err(err)
    }
}

/// A field over points: each row of a CSV (`write_points`' file) drawn at `(x, y)` as a dot
/// coloured by `value` (viridis, its range on a colour bar), the axes at one scale, into an SVG,
/// or a PNG when `out` ends in `.png`; returns the file written. For the deviatoric strain,
/// coordination or mean stress of a column's points, as the thesis's figures 5.14-5.15 show them.
pub fn plot_field(csv: &Path, (x, y): (&str, &str), value: &str, out: PathBuf) -> Result<PathBuf> {
    let (header, rows) = read_csv(csv)?;
    let col = |name: &str| {
        header.iter().position(|h| h == name).ok_or_else(|| GraniteError::Unknown {
            kind: format!("column of {}", csv.display()),
            name: name.into(),
            known: header.join(", "),
        })
    };
    let (xi, yi, vi) = (col(x)?, col(y)?, col(value)?);
    let dots: Vec<(f64, f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((*r.get(xi)?, *r.get(yi)?, *r.get(vi)?)))
        .filter(|(a, b, c)| a.is_finite() && b.is_finite() && c.is_finite())
        .collect();
    if dots.is_empty() {
        return Err(GraniteError::Setup(format!("no finite values of {x}, {y}, {value} in {}", csv.display())));
    }
    let bound = |f: fn(&(f64, f64, f64)) -> f64| {
        dots.iter().map(f).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)))
    };
    let ((x0, x1), (y0, y1), (v0, v1)) = (bound(|d| d.0), bound(|d| d.1), bound(|d| d.2));
    // The axes at one scale, a margin of a twentieth of the larger side around the points.
    let side = (x1 - x0).max(y1 - y0).max(f64::MIN_POSITIVE);
    let pad = 0.05 * side;
    let (x_range, y_range) = ((x0 - pad, x1 + pad), (y0 - pad, y1 + pad));
    let png = is_png("plot_field", &out)?;
    let width = 900u32;
    let plot_width = f64::from(width - 260);
    let height =
        (plot_width * (y_range.1 - y_range.0) / (x_range.1 - x_range.0)).round().clamp(150.0, 1200.0) as u32 + 130;
    // A dot as wide as the points' mean spacing.
    let spacing = ((x1 - x0).max(pad) * (y1 - y0).max(pad) / dots.len() as f64).sqrt();
    let dot = (0.5 * spacing / (x_range.1 - x_range.0) * plot_width).clamp(1.5, 30.0);
    let field = Field {
        x,
        y,
        value,
        dots: &dots,
        x_range,
        y_range,
        value_range: (v0, v1.max(v0 + v0.abs().max(1.0) * 1e-12)),
        dot,
    };
    render("plot_field", &field, &out, png, (width, height))?;
    Ok(out)
}

/// The viridis colour map at `t` in [0, 1] (its ends and three stops between, blended).
fn viridis(t: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 5] =
        [(68.0, 1.0, 84.0), (59.0, 82.0, 139.0), (33.0, 145.0, 140.0), (94.0, 201.0, 98.0), (253.0, 231.0, 37.0)];
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 } * (STOPS.len() - 1) as f64;
    let k = (t.floor() as usize).min(STOPS.len() - 2);
    let f = t - k as f64;
    let (a, b) = (STOPS[k], STOPS[k + 1]);
    let mix = |p: f64, q: f64| (p + f * (q - p)).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// What a field plot shows.
struct Field<'a> {
    x: &'a str,
    y: &'a str,
    value: &'a str,
    dots: &'a [(f64, f64, f64)],
    x_range: (f64, f64),
    y_range: (f64, f64),
    value_range: (f64, f64),
    /// Dot radius in pixels of the SVG.
    dot: f64,
}

impl Picture for Field<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
        scale: u32,
    ) -> std::result::Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        let px = |v: u32| v * scale;
        let (v0, v1) = self.value_range;
        let unit =
            |c: &str| unit_of(c).filter(|u| *u != "1" && *u != "count").map(|u| format!(" [{u}]")).unwrap_or_default();
        root.fill(&WHITE).map_err(e)?;
        let root = root.titled(&format!("{}{}", self.value, unit(self.value)), (FONT, px(20))).map_err(e)?;
        let (plot_area, bar_area) = root.split_horizontally(root.dim_in_pixel().0 - px(140));
        let mut chart = ChartBuilder::on(&plot_area)
            .margin(px(12))
            .x_label_area_size(px(40))
            .y_label_area_size(px(70))
            .build_cartesian_2d(self.x_range.0..self.x_range.1, self.y_range.0..self.y_range.1)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .label_style((FONT, px(12)))
            .axis_desc_style((FONT, px(14)))
            .x_desc(format!("{}{}", self.x, unit(self.x)))
            .y_desc(format!("{}{}", self.y, unit(self.y)))
            .draw()
            .map_err(e)?;
        let radius = (self.dot * f64::from(scale)).round().max(1.0) as i32;
        chart
            .draw_series(
                self.dots.iter().map(|&(a, b, v)| Circle::new((a, b), radius, viridis((v - v0) / (v1 - v0)).filled())),
            )
            .map_err(e)?;
        // The colour bar: the value's range, bottom to top.
        let mut bar = ChartBuilder::on(&bar_area)
            .margin_top(px(12))
            .margin_bottom(px(52))
            .margin_right(px(60))
            .y_label_area_size(px(0))
            .right_y_label_area_size(px(60))
            .build_cartesian_2d(0.0..1.0, v0..v1)
            .map_err(e)?;
        bar.configure_mesh().disable_mesh().disable_x_axis().label_style((FONT, px(11))).draw().map_err(e)?;
        let bands = 64;
        bar.draw_series((0..bands).map(|k| {
            let (lo, hi) = (k as f64 / bands as f64, (k + 1) as f64 / bands as f64);
            Rectangle::new([(0.0, v0 + lo * (v1 - v0)), (1.0, v0 + hi * (v1 - v0))], viridis(0.5 * (lo + hi)).filled())
        }))
        .map_err(e)?;
        root.present().map_err(e)
    }
}

/// The name the plots' text is drawn in: a font built into granite (DejaVu Sans), so that a PNG
/// needs no fonts on the machine. SVG files name the same family; a viewer without it uses its
/// own sans-serif.
const FONT: &str = "sans-serif";

/// Registers the embedded font with the plotting library, once per process.
fn embedded_font() -> Result<()> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok());
    if ok {
        Ok(())
    } else {
        Err(GraniteError::Other("the embedded plot font could not be read".into()))
    }
}

/// What one plot shows: the columns of each panel with their ranges, against `x`.
struct Figure<'a> {
    x: &'a str,
    ys: &'a [String],
    xs: &'a [f64],
    rows: &'a [Vec<f64>],
    /// The column of each name of `ys`.
    yi: &'a [usize],
    /// The members of `ys` in each panel, with the panel's unit.
    panels: &'a [(Option<&'a str>, Vec<usize>)],
    ranges: &'a [(f64, f64)],
    x_range: (f64, f64),
}

impl Picture for Figure<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, plotters::coord::Shift>,
        scale: u32,
    ) -> std::result::Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        let px = |v: u32| v * scale;
        let Figure { x, ys, xs, rows, yi, panels, ranges, x_range: (x0, x1) } = self;
        root.fill(&WHITE).map_err(e)?;
        let root = root.titled(&format!("{} vs {x}", ys.join(", ")), (FONT, px(20))).map_err(e)?;
        let areas = root.split_evenly((panels.len(), 1));
        let palette = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
        let finite = |v: f64| v.is_finite();
        for (((unit, members), area), &(y0, y1)) in panels.iter().zip(&areas).zip(ranges.iter()) {
            let mut chart = ChartBuilder::on(area)
                .margin(px(12))
                .x_label_area_size(px(40))
                .y_label_area_size(px(90))
                .build_cartesian_2d(*x0..*x1, y0..y1)
                .map_err(e)?;
            let names: Vec<&str> = members.iter().map(|&k| ys[k].as_str()).collect();
            chart
                .configure_mesh()
                .label_style((FONT, px(12)))
                .axis_desc_style((FONT, px(14)))
                .x_desc(axis_label(&[x], unit_of(x)))
                .y_desc(axis_label(&names, *unit))
                .draw()
                .map_err(e)?;
            for &k in members {
                let colour = palette[k % palette.len()];
                let points: Vec<(f64, f64)> = rows
                    .iter()
                    .zip(xs.iter())
                    .filter_map(|(r, &xv)| r.get(yi[k]).copied().filter(|y| finite(*y) && finite(xv)).map(|y| (xv, y)))
                    .collect();
                let line = colour.stroke_width(scale);
                chart
                    .draw_series(LineSeries::new(points, line))
                    .map_err(e)?
                    .label(ys[k].clone())
                    .legend(move |(a, b)| PathElement::new(vec![(a, b), (a + 12 * scale as i32, b)], line));
            }
            chart
                .configure_series_labels()
                .label_font((FONT, px(13)))
                .border_style(BLACK)
                .background_style(WHITE)
                .draw()
                .map_err(e)?;
        }
        root.present().map_err(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_columns_have_units_and_axes_say_them() {
        assert_eq!(unit_of("time"), Some("s"));
        assert_eq!(unit_of("runout"), Some("m"));
        assert_eq!(unit_of("energy_kinetic"), unit_of("kinetic_energy"));
        assert_eq!(unit_of("q"), Some("Pa"));
        assert_eq!(unit_of("my_column"), None);
        assert_eq!(axis_label(&["runout"], Some("m")), "runout [m]");
        assert_eq!(axis_label(&["void_ratio"], Some("1")), "void_ratio");
    }
}

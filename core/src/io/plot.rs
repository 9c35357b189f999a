//! `granite plot`: line plots of series.csv columns as SVG, so energies, runout and stress paths
//! can be looked at without other tools.

use crate::error::{GraniteError, Result};
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

/// Plots `ys` against `x` from a CSV file into an SVG; returns the file written.
pub fn plot(csv: &Path, x: &str, ys: &[String], out: Option<PathBuf>) -> Result<PathBuf> {
    let (header, rows) = read_csv(csv)?;
    let col = |name: &str| {
        header.iter().position(|h| h == name).ok_or_else(|| GraniteError::Unknown {
            kind: format!("column of {}", csv.display()),
            name: name.into(),
            known: header.join(", "),
        })
    };
    let xi = col(x)?;
    let yi: Vec<usize> = ys.iter().map(|y| col(y)).collect::<Result<_>>()?;
    if yi.is_empty() {
        return Err(GraniteError::Setup("give at least one column to plot with --y".into()));
    }
    let finite = |v: f64| v.is_finite();
    let xs: Vec<f64> = rows.iter().map(|r| r.get(xi).copied().unwrap_or(f64::NAN)).collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for (r, &xv) in rows.iter().zip(&xs) {
        for &c in &yi {
            let yv = r.get(c).copied().unwrap_or(f64::NAN);
            if finite(xv) && finite(yv) {
                x0 = x0.min(xv);
                x1 = x1.max(xv);
                y0 = y0.min(yv);
                y1 = y1.max(yv);
            }
        }
    }
    if !(x0.is_finite() && y0.is_finite()) {
        return Err(GraniteError::Setup(format!("no finite values to plot in {}", csv.display())));
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y1 = y0 + y0.abs().max(1.0) * 1e-3;
    }
    let pad = 0.05 * (y1 - y0);
    let out = out.unwrap_or_else(|| csv.with_file_name(format!("plot_{}.svg", ys.join("_"))));
    {
        let root = SVGBackend::new(&out, (900, 560)).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| GraniteError::Other(format!("plot {}: {e}", out.display()));
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{} vs {x}", ys.join(", ")), ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(80)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
            .map_err(|e| err(&e))?;
        chart.configure_mesh().x_desc(x).draw().map_err(|e| err(&e))?;
        let palette = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
        for (k, &c) in yi.iter().enumerate() {
            let colour = palette[k % palette.len()];
            let points: Vec<(f64, f64)> = rows
                .iter()
                .zip(&xs)
                .filter_map(|(r, &xv)| r.get(c).copied().filter(|y| finite(*y) && finite(xv)).map(|y| (xv, y)))
                .collect();
            chart
                .draw_series(LineSeries::new(points, &colour))
                .map_err(|e| err(&e))?
                .label(ys[k].clone())
                .legend(move |(a, b)| PathElement::new(vec![(a, b), (a + 20, b)], colour));
        }
        chart.configure_series_labels().border_style(BLACK).background_style(WHITE).draw().map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    Ok(out)
}

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
        "max_height" | "max_x" | "lx" | "runout" => "m",
        "p" | "q" | "mean_stress" | "deviatoric_stress" => "Pa",
        _ if c.ends_with("_energy") || c.starts_with("energy_") || c == "boundary_work" => "J (2D MPM: J/m)",
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

/// Plots `ys` against `x` from a CSV file into an SVG; returns the file written. Columns of
/// different units go to panels of their own, one above the other, each axis labelled with its
/// unit: one quantity per axis.
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
    {
        let height = 120 + 380 * panels.len() as u32;
        let root = SVGBackend::new(&out, (900, height)).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| GraniteError::Other(format!("plot {}: {e}", out.display()));
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root.titled(&format!("{} vs {x}", ys.join(", ")), ("sans-serif", 20)).map_err(|e| err(&e))?;
        let areas = root.split_evenly((panels.len(), 1));
        let palette = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
        for (((unit, members), area), &(y0, y1)) in panels.iter().zip(&areas).zip(&ranges) {
            let mut chart = ChartBuilder::on(area)
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(90)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| err(&e))?;
            let names: Vec<&str> = members.iter().map(|&k| ys[k].as_str()).collect();
            chart
                .configure_mesh()
                .x_desc(axis_label(&[x], unit_of(x)))
                .y_desc(axis_label(&names, *unit))
                .draw()
                .map_err(|e| err(&e))?;
            for &k in members {
                let colour = palette[k % palette.len()];
                let points: Vec<(f64, f64)> = rows
                    .iter()
                    .zip(&xs)
                    .filter_map(|(r, &xv)| r.get(yi[k]).copied().filter(|y| finite(*y) && finite(xv)).map(|y| (xv, y)))
                    .collect();
                chart
                    .draw_series(LineSeries::new(points, &colour))
                    .map_err(|e| err(&e))?
                    .label(ys[k].clone())
                    .legend(move |(a, b)| PathElement::new(vec![(a, b), (a + 20, b)], colour));
            }
            chart.configure_series_labels().border_style(BLACK).background_style(WHITE).draw().map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    Ok(out)
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

//! The report of a serial-arm calibration: position errors of every step (nominal,
//! geometric, each effect family) in sample and on held-out poses, the effects with their
//! parameters, the parameters the identifiability analysis dropped, the periodograms; and
//! its HTML page with plots (residual against each joint angle, periodograms) drawn with
//! plotters.

use plotters::prelude::*;
use serde::Serialize;

use crate::discovery::families::Periodogram;

/// Summary of position errors (mm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorStats {
    /// RMS (mm).
    pub rms_mm: f64,
    /// Mean (mm).
    pub mean_mm: f64,
    /// Largest (mm).
    pub max_mm: f64,
    /// Number of errors.
    pub count: usize,
}

impl ErrorStats {
    /// Statistics of `errors` (mm); zeros for none.
    pub fn of(errors: &[f64]) -> Self {
        let n = errors.len().max(1) as f64;
        ErrorStats {
            rms_mm: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
            mean_mm: errors.iter().sum::<f64>() / n,
            max_mm: errors.iter().copied().fold(0.0, f64::max),
            count: errors.len(),
        }
    }
}

/// One step of the calibration.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepReport {
    /// `nominal`, `geometric` or `+ <family>`.
    pub model: String,
    /// Errors on the fitted poses.
    pub fit: ErrorStats,
    /// Errors on the held-out poses (`None` when nothing was held out).
    pub held_out: Option<ErrorStats>,
    /// Parameters fitted.
    pub parameters: usize,
}

/// One effect family added.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FamilyReport {
    /// Label, e.g. `periodic elbow_joint`.
    pub label: String,
    /// Class.
    pub class: String,
    /// Relative ridge it was fitted with.
    pub ridge: f64,
    /// Cross-validated whitened sum of squares before and after (training poses).
    pub cross_validated: [f64; 2],
    /// Its parameters: name, value, unit.
    pub parameters: Vec<(String, f64, String)>,
    /// Held-out position RMS before and after it (mm).
    pub held_out_rms_mm: Option<[f64; 2]>,
}

/// The whole report (`report.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SerialReport {
    /// The recording.
    pub recording: String,
    /// The robot's name.
    pub robot: String,
    /// Poses fitted and held out.
    pub poses: [usize; 2],
    /// Whether orientations were fitted.
    pub use_orientation: bool,
    /// Every step.
    pub steps: Vec<StepReport>,
    /// The effect families added, in order.
    pub effects: Vec<FamilyReport>,
    /// Families best in a round that did not win held out.
    pub rejected: Vec<String>,
    /// Geometric parameters dropped by the identifiability analysis (minimal set).
    pub dropped_parameters: Vec<String>,
    /// Parameters the joint fit fixed.
    pub fixed_parameters: Vec<String>,
    /// Condition number of the geometric fit.
    pub condition_number: f64,
    /// Periodograms of the geometric fit's residual.
    pub periodograms_before: Vec<Periodogram>,
    /// Periodograms of the final residual.
    pub periodograms_after: Vec<Periodogram>,
    /// Wall time (s).
    pub run_time_s: f64,
}

/// One joint's scatter: angle (rad or mm) against position error (mm), per model.
#[derive(Debug, Clone, PartialEq)]
pub struct JointScatter {
    /// Joint name.
    pub joint: String,
    /// Per model: its label and the (joint value, error) points.
    pub series: Vec<(String, Vec<(f64, f64)>)>,
}

const COLOURS: [RGBColor; 3] = [
    RGBColor(200, 60, 40),
    RGBColor(40, 90, 200),
    RGBColor(40, 150, 60),
];

fn scatter_svg(scatter: &JointScatter) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (520, 300)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let points = scatter.series.iter().flat_map(|(_, p)| p);
        let (mut x0, mut x1, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for (x, y) in points {
            x0 = x0.min(*x);
            x1 = x1.max(*x);
            y1 = y1.max(*y);
        }
        if !x0.is_finite() || x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("position error vs {}", scatter.joint),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(x0..x1, 0.0..(y1 * 1.05).max(1e-3))
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(scatter.joint.as_str())
            .y_desc("mm")
            .draw()
            .map_err(|e| e.to_string())?;
        for (k, (label, points)) in scatter.series.iter().enumerate() {
            let colour = COLOURS[k % COLOURS.len()];
            chart
                .draw_series(
                    points
                        .iter()
                        .map(|(x, y)| Circle::new((*x, *y), 1, colour.filled())),
                )
                .map_err(|e| e.to_string())?
                .label(label.as_str())
                .legend(move |(x, y)| Circle::new((x, y), 3, colour.filled()));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

fn periodogram_svg(before: &Periodogram, after: Option<&Periodogram>) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (520, 260)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let top = before
            .power
            .iter()
            .chain(after.map(|a| a.power.as_slice()).unwrap_or_default())
            .fold(before.floor, |m, p| m.max(*p));
        let h_max = before.harmonics.iter().copied().fold(1.0, f64::max);
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("periodogram, {}", before.family),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..h_max + 1.0, (0.1f64..top * 2.0).log_scale())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("harmonic of the joint angle")
            .y_desc("power (Δχ²)")
            .draw()
            .map_err(|e| e.to_string())?;
        let series = [
            Some(("geometric residual", before)),
            after.map(|a| ("final residual", a)),
        ];
        for (k, (label, p)) in series.into_iter().flatten().enumerate() {
            let colour = COLOURS[k];
            chart
                .draw_series(LineSeries::new(
                    p.harmonics
                        .iter()
                        .zip(&p.power)
                        .map(|(h, w)| (*h, w.max(0.1))),
                    colour.stroke_width(2),
                ))
                .map_err(|e| e.to_string())?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], colour));
        }
        chart
            .draw_series(LineSeries::new(
                [(0.0, before.floor), (h_max + 1.0, before.floor)],
                BLACK.mix(0.5),
            ))
            .map_err(|e| e.to_string())?
            .label("noise floor")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], BLACK.mix(0.5)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn cell(stats: Option<&ErrorStats>) -> String {
    stats.map_or("<td>–</td><td>–</td><td>–</td>".into(), |s| {
        format!(
            "<td>{:.3}</td><td>{:.3}</td><td>{:.3}</td>",
            s.rms_mm, s.mean_mm, s.max_mm
        )
    })
}

/// The HTML page of `report` with the residual scatters of `scatters`.
pub fn html(report: &SerialReport, scatters: &[JointScatter]) -> Result<String, String> {
    let mut page = format!(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{robot} calibration</title>\
         <style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}td,th{{padding:2px 8px;\
         text-align:right}}table{{border-collapse:collapse}}tr:nth-child(even){{background:#f3f3f3}}\
         </style></head><body><h1>{robot}: calibration from measured poses</h1>\
         <p>{rec}: {fit} poses fitted, {held} held out; orientations {orient}; {time:.2} s.</p>\
         <h2>Position error per step (mm)</h2><table><tr><th>model</th><th>parameters</th>\
         <th>fit RMS</th><th>mean</th><th>max</th><th>held-out RMS</th><th>mean</th><th>max</th></tr>",
        robot = escape(&report.robot),
        rec = escape(&report.recording),
        fit = report.poses[0],
        held = report.poses[1],
        orient = if report.use_orientation { "fitted" } else { "not fitted (positions only)" },
        time = report.run_time_s,
    );
    for step in &report.steps {
        page.push_str(&format!(
            "<tr><td style=\"text-align:left\">{}</td><td>{}</td>{}{}</tr>",
            escape(&step.model),
            step.parameters,
            cell(Some(&step.fit)),
            cell(step.held_out.as_ref())
        ));
    }
    page.push_str("</table><h2>Effects added</h2>");
    for effect in &report.effects {
        page.push_str(&format!(
            "<h3>{}</h3><p>class {}, relative ridge {:.0e}, cross-validated χ² {:.0} → {:.0}{}</p><table>",
            escape(&effect.label),
            effect.class,
            effect.ridge,
            effect.cross_validated[0],
            effect.cross_validated[1],
            effect.held_out_rms_mm.map_or(String::new(), |[a, b]| format!(
                "; held-out RMS {a:.3} → {b:.3} mm"
            )),
        ));
        for (name, value, unit) in &effect.parameters {
            page.push_str(&format!(
                "<tr><td style=\"text-align:left\">{}</td><td>{value:.4e}</td><td>{}</td></tr>",
                escape(name),
                escape(unit)
            ));
        }
        page.push_str("</table>");
    }
    page.push_str(&format!(
        "<p>Rejected (best in a round, no held-out gain): {}</p>\
         <p>Dropped by the identifiability analysis (minimal set): {}</p>",
        escape(&report.rejected.join(", ")),
        escape(&report.dropped_parameters.join(", ")),
    ));
    page.push_str("<h2>Residual against each joint</h2>");
    for scatter in scatters {
        page.push_str(&scatter_svg(scatter)?);
    }
    page.push_str("<h2>Periodograms</h2>");
    for before in &report.periodograms_before {
        let after = report
            .periodograms_after
            .iter()
            .find(|a| a.family == before.family);
        page.push_str(&periodogram_svg(before, after)?);
    }
    page.push_str("</body></html>\n");
    Ok(page)
}

//! The residual-loop section of `report.html`: effects added, held-out error per step, the
//! residual against each joint angle and its histogram against the tracker noise, before
//! and after, and what is left unexplained.

use std::fmt::Write;

use crate::discovery::Correlate;
use crate::report::discovery::StepMetrics;
use crate::report::plots::{ResidualPicture, HISTOGRAM_BIN, HISTOGRAM_LOW};
use crate::report::svg;
use crate::report::Report;

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn correlate_rows(out: &mut String, rows: &[Correlate]) {
    out.push_str(
        "<table><tr><th>signal</th><th>what</th><th>in library</th><th>Δχ²</th>\
         <th>explained share</th><th>held-out gain</th><th>significant</th></tr>\n",
    );
    for c in rows {
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.1}</td><td>{:.4}</td><td>{:.1}</td><td>{}</td></tr>",
            escape(&c.label),
            escape(&c.signal),
            if c.in_library { "yes" } else { "no" },
            c.chi2_gain,
            c.explained_share,
            c.held_out_gain,
            if c.significant { "yes" } else { "no" }
        );
    }
    out.push_str("</table>\n");
}

/// Colours of the directions of motion: moving down, moving up, unknown.
const DIRECTION_PALETTE: [&str; 3] = ["#1f5fb4", "#d9730d", "#999999"];

/// Scatter plots of the joint errors against each joint angle, one row per picture, with a
/// common vertical range per joint; points and binned means coloured by the joint's
/// direction of motion (a backlash separates the two directions).
fn joint_plots(out: &mut String, pictures: &[&ResidualPicture]) {
    for j in 0..5 {
        let all = || pictures.iter().flat_map(|p| p.joint_errors[j].iter());
        let x_range = svg::padded_range(all().map(|p| p.angle));
        let y_range = svg::padded_range(all().map(|p| p.error_mrad));
        out.push_str("<div>");
        for picture in pictures {
            let points: Vec<(f64, f64, usize)> = picture.joint_errors[j]
                .iter()
                .map(|p| (p.angle, p.error_mrad, p.class))
                .collect();
            let lines: Vec<(usize, &[(f64, f64)])> = picture.binned_means[j]
                .iter()
                .enumerate()
                .map(|(class, line)| (class, line.as_slice()))
                .collect();
            let title = format!("θ{}: {}", j + 1, picture.label);
            let x_label = format!("θ{} (rad)", j + 1);
            out.push_str(
                &svg::Scatter {
                    title: &title,
                    x_label: &x_label,
                    y_label: "joint error (mrad)",
                    points: &points,
                    lines: &lines,
                    palette: &DIRECTION_PALETTE,
                    x_range,
                    y_range,
                }
                .render(),
            );
        }
        out.push_str("</div>\n");
    }
}

/// Per joint: the joint error per direction of motion, and direction × joint error along
/// the travel since the last reversal, before and after the loop (a play the model lacks
/// splits the directions and ramps over the first gap-width of travel).
fn hysteresis_plots(out: &mut String, pictures: &[&ResidualPicture]) {
    out.push_str(
        "<h3>Hysteresis: residual against the direction of motion and the travel since the \
         last reversal</h3><table><tr><th>joint</th><th>model</th><th>moving down mrad</th>\
         <th>moving up mrad</th><th>up − down mrad</th></tr>\n",
    );
    let mrad = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.3}"));
    for j in 0..5 {
        for picture in pictures {
            let h = &picture.hysteresis[j];
            let _ = writeln!(
                out,
                "<tr><td>θ{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                j + 1,
                escape(&picture.label),
                mrad(h.mean_by_direction_mrad[0]),
                mrad(h.mean_by_direction_mrad[1]),
                mrad(h.direction_split_mrad()),
            );
        }
    }
    out.push_str("</table>\n<div>");
    for j in 0..5 {
        let series: Vec<Vec<(f64, f64)>> = pictures
            .iter()
            .map(|p| {
                p.hysteresis[j]
                    .by_travel_mrad
                    .iter()
                    .map(|&(travel, error, _)| (travel, error))
                    .collect()
            })
            .collect();
        let points: Vec<(f64, f64, usize)> = series
            .iter()
            .enumerate()
            .flat_map(|(k, line)| line.iter().map(move |&(x, y)| (x, y, k)))
            .collect();
        let lines: Vec<(usize, &[(f64, f64)])> = series
            .iter()
            .enumerate()
            .map(|(k, line)| (k, line.as_slice()))
            .collect();
        let title = format!("θ{}: before (grey), after (blue)", j + 1);
        out.push_str(
            &svg::Scatter {
                title: &title,
                x_label: "travel since the last reversal (mrad)",
                y_label: "direction × joint error (mrad)",
                points: &points,
                lines: &lines,
                palette: &["#777777", "#1f5fb4"],
                x_range: svg::padded_range(points.iter().map(|p| p.0)),
                y_range: svg::padded_range(points.iter().map(|p| p.1)),
            }
            .render(),
        );
    }
    out.push_str("</div>\n");
}

/// The section, or an empty string when the loop did not run.
pub fn section(report: &Report) -> String {
    let f = &report.r#final;
    let mut out = String::from("<h2>Residual loop: effects beyond the paper model</h2>\n");
    let _ = writeln!(out, "<p><b>{}</b></p>", escape(&f.verdict));
    if report.effects.is_empty() {
        out.push_str("<p>No effect was added.</p>\n");
    } else {
        out.push_str(
            "<table><tr><th>effect</th><th>parameters (± std dev)</th><th>Δχ² / threshold</th>\
             <th>held-out gain (folds improved)</th><th>held-out tip before → after mm</th>\
             <th>front / back residual before → after mm</th></tr>\n",
        );
        for e in &report.effects {
            let parameters: Vec<String> = e
                .parameters
                .iter()
                .map(|p| {
                    let std = p.std_dev.map_or("fixed".into(), |s| format!("{s:.2e}"));
                    format!("{} = {:.4e} ± {std} {}", p.name, p.value, p.unit)
                })
                .collect();
            let tip = |m: &StepMetrics| {
                m.held_out_tip_mm()
                    .map_or("–".into(), |v| format!("{v:.4}"))
            };
            let _ = writeln!(
                out,
                "<tr><td>{}</td><td>{}</td><td>{:.1} / {:.1}</td><td>{:.1} ({}/{})</td>\
                 <td>{} → {}</td><td>{:.4} / {:.4} → {:.4} / {:.4}</td></tr>",
                escape(&e.label),
                escape(&parameters.join("; ")),
                e.evidence.chi2_gain,
                e.evidence.chi2_threshold,
                e.evidence.held_out_gain,
                e.evidence.folds_improved,
                e.evidence.folds,
                tip(&e.before),
                tip(&e.after),
                e.before.residual_rms.front_mm,
                e.before.residual_rms.back_mm,
                e.after.residual_rms.front_mm,
                e.after.residual_rms.back_mm
            );
        }
        out.push_str("</table>\n");
    }
    let mut rows: Vec<(String, Option<f64>)> = report
        .residual_rms
        .first()
        .map(|r| {
            (
                "nominal".to_string(),
                r.validation_marker_tip.map(|e| e.rms_mm),
            )
        })
        .into_iter()
        .collect();
    rows.extend(f.steps.iter().map(|s| (s.label.clone(), s.held_out_tip_mm)));
    out.push_str(&svg::bars(
        "Held-out tip error per step (validation holds, RMS)",
        "mm",
        &rows,
    ));
    let cross: Vec<(String, Option<f64>)> = f
        .steps
        .iter()
        .map(|s| (s.label.clone(), s.cross_validated_tip_mm))
        .collect();
    out.push_str(&svg::bars(
        "Cross-validated tip error per step (tip phase, RMS)",
        "mm",
        &cross,
    ));
    let pictures: Vec<&ResidualPicture> = [f.plots.before.as_ref(), f.plots.after.as_ref()]
        .into_iter()
        .flatten()
        .collect();
    if !pictures.is_empty() {
        out.push_str(
            "<h3>Residual against each joint angle</h3><p>Each point is one tracker frame: the \
             joint errors that best explain its marker residuals; lines are their means along \
             the joint angle. Colour: the joint moving down (blue), up (orange), or not yet \
             moved (grey).</p>\n",
        );
        joint_plots(&mut out, &pictures);
        hysteresis_plots(&mut out, &pictures);
        let colours = ["#777", "#1f5fb4"];
        let series: Vec<svg::DensitySeries<'_>> = pictures
            .iter()
            .zip(colours)
            .map(|(p, colour)| svg::DensitySeries {
                name: &p.label,
                colour,
                density: &p.density,
            })
            .collect();
        out.push_str("<h3>Residual against the tracker noise</h3>\n");
        out.push_str(&svg::histogram(
            "whitened residual components",
            "residual / tracker noise at rest",
            HISTOGRAM_LOW,
            HISTOGRAM_BIN,
            &series,
        ));
        for p in &pictures {
            let _ = writeln!(
                out,
                "<p>{}: RMS {:.3} × tracker noise, {:.2} % beyond ±6.</p>",
                escape(&p.label),
                p.whitened_rms,
                100.0 * p.outside
            );
        }
    }
    out.push_str(
        "<h3>Residual against the tracker noise, per tool</h3><table><tr><th>tool</th>\
        <th>variance ratio</th><th>dof</th><th>reference dof</th><th>p</th><th>noise?</th></tr>\n",
    );
    for t in &f.metrics.noise_test {
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td>{:.3}</td><td>{:.0}</td><td>{:.0}</td><td>{:.2e}</td><td>{}</td></tr>",
            t.tool,
            t.variance_ratio,
            t.dof,
            t.reference_dof,
            t.p_value,
            if t.is_noise { "yes" } else { "no" }
        );
    }
    out.push_str("</table>\n");
    if !f.leads.is_empty() {
        out.push_str("<h3>Structure outside the effect library (not claimed)</h3>\n");
        correlate_rows(&mut out, &f.leads);
    }
    if !f.explained_leads.is_empty() {
        out.push_str(
            "<h3>Structure outside the library on the way, explained by the effects added \
             after it</h3>\n",
        );
        correlate_rows(&mut out, &f.explained_leads);
    }
    out.push_str("<h3>Strongest correlates of the final residual</h3>\n");
    correlate_rows(&mut out, &f.strongest_correlates);
    out
}

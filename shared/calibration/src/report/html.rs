//! A static, self-contained HTML rendering of the report.

use std::fmt::Write;

use crate::math::stats::ErrorSummary;
use crate::report::{ModelResiduals, Report};

/// Escapes text for HTML.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn number(value: f64) -> String {
    if !value.is_finite() {
        return "–".into();
    }
    let magnitude = value.abs();
    if magnitude != 0.0 && !(1e-3..1e5).contains(&magnitude) {
        format!("{value:.4e}")
    } else {
        format!("{value:.5}")
    }
}

fn tip(error: &Option<ErrorSummary>) -> String {
    error.map_or("–".into(), |e| {
        format!("{} / {} ({})", number(e.rms_mm), number(e.max_mm), e.count)
    })
}

fn residual_row(out: &mut String, r: &ModelResiduals) {
    let _ = writeln!(
        out,
        "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
         <td>{}</td><td>{}</td></tr>",
        escape(&r.model),
        number(r.front_mm),
        number(r.front_deg),
        number(r.back_mm),
        number(r.back_deg),
        number(r.tip_mm),
        number(r.validation_front_mm),
        number(r.validation_back_mm),
        tip(&r.validation_marker_tip)
    );
}

/// Renders the report as a standalone HTML page.
pub fn render(report: &Report) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>SABR calibration</title>\
         <style>body{{font-family:sans-serif;margin:2em;max-width:70em}}\
         table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #bbb;\
         padding:.2em .6em;text-align:right}}th{{background:#eee}}td:first-child{{text-align:left}}\
         </style></head><body><h1>SABR calibration</h1>"
    );
    let _ = writeln!(
        out,
        "<p>Recording <code>{}</code>; run time {} s.</p>",
        escape(&report.recording),
        number(report.run_time_s)
    );
    let v = &report.validation;
    let _ = writeln!(
        out,
        "<h2>Summary</h2><table><tr><th>tracker latency (ms)</th><td>{} ± {}</td></tr>\
         <tr><th>tip error, joint fit: RMS / max (n) mm</th><td>{}</td></tr>\
         <tr><th>source of the tip error</th><td>{}</td></tr>\
         <tr><th>cross-validated tip (tip phase) mm</th><td>{}</td></tr>\
         <tr><th>tip reading noise / cross-validated excess mm</th><td>{} / {}</td></tr>\
         <tr><th>predicted tip std at validation holds mm</th><td>{}</td></tr></table><p>{}</p>",
        number(report.latency_ms),
        number(report.latency_std_ms),
        tip(&v.tip_error),
        escape(&v.tip_error_source),
        tip(&v.cross_validated_tip),
        number(v.tip_reading_noise_mm),
        v.cross_validated_excess_mm.map_or("–".into(), number),
        tip(&v.predicted_tip_std),
        escape(&v.method)
    );
    let _ = writeln!(
        out,
        "<h2>Residual RMS per tool</h2><table><tr><th>model</th><th>front mm</th>\
         <th>front °</th><th>back mm</th><th>back °</th><th>tip mm</th>\
         <th>held-out front mm</th><th>held-out back mm</th>\
         <th>held-out marker tip RMS / max (n) mm</th></tr>"
    );
    for r in &report.residual_rms {
        residual_row(&mut out, r);
    }
    out.push_str(
        "</table>\n<h2>Parameters</h2><table><tr><th>parameter</th><th>unit</th>\
        <th>nominal</th><th>stepwise</th><th>joint fit</th><th>std dev</th></tr>\n",
    );
    for p in &report.parameters {
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&p.name),
            escape(&p.unit),
            number(p.nominal),
            number(p.stepwise),
            number(p.joint),
            p.std_dev.map_or("fixed".into(), number)
        );
    }
    let id = &report.identifiability;
    let _ = writeln!(
        out,
        "</table><h2>Identifiability</h2><p>Rank {} of {} parameters; condition number {} \
         (column-scaled weighted Jacobian); reduced χ² {}.</p>",
        id.rank,
        id.parameters,
        number(id.condition_number),
        number(id.reduced_chi_squared)
    );
    if id.fixed.is_empty() {
        out.push_str("<p>No direction had to be fixed.</p>\n");
    }
    for f in &id.fixed {
        let names: Vec<String> = f
            .direction
            .parameters
            .iter()
            .map(|(n, c)| format!("{n} ({c:.2})"))
            .collect();
        let _ = writeln!(
            out,
            "<p>Fixed <code>{}</code> at {}: near-null direction involving {}.</p>",
            escape(&f.name),
            number(f.value),
            escape(&names.join(", "))
        );
    }
    for (a, b, rho) in &id.strong_correlations {
        let _ = writeln!(
            out,
            "<p>Strong correlation {} ↔ {}: {:.3}</p>",
            escape(a),
            escape(b),
            rho
        );
    }
    let t = &report.time_sync;
    let d = &report.data;
    let _ = writeln!(
        out,
        "<h2>Data and time synchronisation</h2><table>\
         <tr><th>tracker tick ms</th><td>{}</td></tr><tr><th>arrival jitter ms</th><td>{}</td></tr>\
         <tr><th>model-free latency ms</th><td>{}</td></tr><tr><th>encoder interval ms</th><td>{}</td></tr>\
         <tr><th>tracker frames / without base / without robot tools</th><td>{} / {} / {}</td></tr>\
         <tr><th>frames rejected for encoder gaps</th><td>{}</td></tr>\
         <tr><th>dwell / excitation / tip readings / validation frames / holds</th><td>{} / {} / {} / {} / {}</td></tr>\
         <tr><th>down-weighted measurements</th><td>{}</td></tr></table>",
        number(t.tracker_tick_ms),
        number(t.arrival_jitter_ms),
        number(t.model_free_latency_ms),
        number(t.encoder_interval_ms),
        t.frames.frames_total,
        t.frames.frames_without_base,
        t.frames.frames_without_robot_tools,
        t.frames_rejected_encoder_gap,
        d.dwell_frames,
        d.excitation_frames,
        d.tip_readings,
        d.validation_frames,
        d.validation_holds,
        d.downweighted_measurements
    );
    out.push_str(&crate::report::discovery_html::section(report));
    out.push_str("</body></html>");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escaping_and_number_formatting() {
        assert_eq!(escape("<a&b>"), "&lt;a&amp;b&gt;");
        assert_eq!(number(f64::NAN), "–");
        assert_eq!(number(1.5), "1.50000");
        assert_eq!(number(2.5e-6), "2.5000e-6");
    }
}

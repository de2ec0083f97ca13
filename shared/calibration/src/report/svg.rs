//! Minimal inline SVG charts for the HTML report: scatter plots, a histogram with a density
//! curve, and horizontal bars. Each chart is a self-contained `<svg>` element.

use std::fmt::Write;

/// Chart size (px) and the inner margins for the axes.
const WIDTH: f64 = 320.0;
const HEIGHT: f64 = 220.0;
const LEFT: f64 = 52.0;
const RIGHT: f64 = 10.0;
const TOP: f64 = 24.0;
const BOTTOM: f64 = 36.0;

/// A data range mapped onto a pixel range.
#[derive(Debug, Clone, Copy)]
struct Axis {
    low: f64,
    high: f64,
    from_px: f64,
    to_px: f64,
}

impl Axis {
    fn new(low: f64, high: f64, from_px: f64, to_px: f64) -> Self {
        let (low, high) = if high > low {
            (low, high)
        } else {
            (low - 1.0, low + 1.0)
        };
        Self {
            low,
            high,
            from_px,
            to_px,
        }
    }

    fn px(&self, value: f64) -> f64 {
        self.from_px + (value - self.low) / (self.high - self.low) * (self.to_px - self.from_px)
    }

    /// About five round tick values inside the range.
    fn ticks(&self) -> Vec<f64> {
        let raw = (self.high - self.low) / 5.0;
        let magnitude = 10f64.powf(raw.log10().floor());
        let step = [1.0, 2.0, 5.0, 10.0]
            .iter()
            .map(|m| m * magnitude)
            .find(|s| *s >= raw)
            .unwrap_or(10.0 * magnitude);
        let first = (self.low / step).ceil() as i64;
        let last = (self.high / step + 1e-9).floor() as i64;
        (first..=last).map(|k| k as f64 * step).collect()
    }
}

/// Range of values with a little padding; `(−1, 1)` when empty.
pub fn padded_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (low, high) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !low.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = 0.05 * (high - low).max(1e-12);
    (low - pad, high + pad)
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn tick_label(value: f64) -> String {
    let text = format!("{value:.3}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Opens a chart: frame, title, axis labels and ticks.
fn frame(out: &mut String, title: &str, x_label: &str, y_label: &str, x: &Axis, y: &Axis) {
    let _ = write!(
        out,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH}\" height=\"{HEIGHT}\" \
         viewBox=\"0 0 {WIDTH} {HEIGHT}\" font-family=\"sans-serif\" font-size=\"10\">\
         <text x=\"{}\" y=\"14\" text-anchor=\"middle\" font-size=\"11\">{}</text>\
         <rect x=\"{LEFT}\" y=\"{TOP}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#888\"/>",
        WIDTH / 2.0,
        escape(title),
        WIDTH - LEFT - RIGHT,
        HEIGHT - TOP - BOTTOM
    );
    for t in x.ticks() {
        let px = x.px(t);
        let _ = write!(
            out,
            "<line x1=\"{px:.1}\" y1=\"{}\" x2=\"{px:.1}\" y2=\"{}\" stroke=\"#888\"/>\
             <text x=\"{px:.1}\" y=\"{}\" text-anchor=\"middle\">{}</text>",
            HEIGHT - BOTTOM,
            HEIGHT - BOTTOM + 4.0,
            HEIGHT - BOTTOM + 14.0,
            tick_label(t)
        );
    }
    for t in y.ticks() {
        let py = y.px(t);
        let _ = write!(
            out,
            "<line x1=\"{}\" y1=\"{py:.1}\" x2=\"{LEFT}\" y2=\"{py:.1}\" stroke=\"#888\"/>\
             <text x=\"{}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            LEFT - 4.0,
            LEFT - 6.0,
            py + 3.0,
            tick_label(t)
        );
    }
    let _ = write!(
        out,
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\
         <text transform=\"translate(12 {}) rotate(-90)\" text-anchor=\"middle\">{}</text>",
        LEFT + (WIDTH - LEFT - RIGHT) / 2.0,
        HEIGHT - 6.0,
        escape(x_label),
        TOP + (HEIGHT - TOP - BOTTOM) / 2.0,
        escape(y_label)
    );
}

/// A scatter plot: points of a few classes (one colour each) and, per class, a line.
pub struct Scatter<'a> {
    /// Title.
    pub title: &'a str,
    /// Horizontal axis label.
    pub x_label: &'a str,
    /// Vertical axis label.
    pub y_label: &'a str,
    /// Points `(x, y, class)`.
    pub points: &'a [(f64, f64, usize)],
    /// Lines (polylines) by class.
    pub lines: &'a [(usize, &'a [(f64, f64)])],
    /// Colour of each class.
    pub palette: &'a [&'a str],
    /// Horizontal range.
    pub x_range: (f64, f64),
    /// Vertical range (points beyond it are drawn at its edge).
    pub y_range: (f64, f64),
}

impl Scatter<'_> {
    /// The chart.
    pub fn render(&self) -> String {
        let x = Axis::new(self.x_range.0, self.x_range.1, LEFT, WIDTH - RIGHT);
        let y = Axis::new(self.y_range.0, self.y_range.1, HEIGHT - BOTTOM, TOP);
        let mut out = String::new();
        frame(&mut out, self.title, self.x_label, self.y_label, &x, &y);
        if (y.low..=y.high).contains(&0.0) {
            let py = y.px(0.0);
            let _ = write!(
                out,
                "<line x1=\"{LEFT}\" y1=\"{py:.1}\" x2=\"{}\" y2=\"{py:.1}\" stroke=\"#ccc\"/>",
                WIDTH - RIGHT
            );
        }
        let colour = |class: usize| self.palette.get(class).copied().unwrap_or("#000");
        for (px, py, class) in self.points {
            let _ = write!(
                out,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"1.4\" fill=\"{}\" fill-opacity=\"0.45\"/>",
                x.px(*px),
                y.px(py.clamp(y.low, y.high)),
                colour(*class)
            );
        }
        for (class, line) in self.lines {
            let points: Vec<String> = line
                .iter()
                .map(|(a, b)| format!("{:.1},{:.1}", x.px(*a), y.px(b.clamp(y.low, y.high))))
                .collect();
            let _ = write!(
                out,
                "<polyline points=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"2\"/>",
                points.join(" "),
                colour(*class)
            );
        }
        out.push_str("</svg>");
        out
    }
}

/// A histogram series: densities per bin.
pub struct DensitySeries<'a> {
    /// Legend text.
    pub name: &'a str,
    /// Stroke colour.
    pub colour: &'a str,
    /// Density of each bin.
    pub density: &'a [f64],
}

/// Step histograms of several series over bins `low + k·width`, with the standard normal
/// density as reference.
pub fn histogram(
    title: &str,
    x_label: &str,
    low: f64,
    width: f64,
    series: &[DensitySeries<'_>],
) -> String {
    let bins = series.first().map_or(0, |s| s.density.len());
    let high = low + width * bins as f64;
    let peak = series
        .iter()
        .flat_map(|s| s.density.iter().copied())
        .fold(0.4f64, f64::max);
    let x = Axis::new(low, high, LEFT, WIDTH - RIGHT);
    let y = Axis::new(0.0, peak * 1.05, HEIGHT - BOTTOM, TOP);
    let mut out = String::new();
    frame(&mut out, title, x_label, "density", &x, &y);
    let normal: Vec<String> = (0..=200)
        .map(|k| {
            let v = low + (high - low) * k as f64 / 200.0;
            let d = (-0.5 * v * v).exp() / (2.0 * std::f64::consts::PI).sqrt();
            format!("{:.1},{:.1}", x.px(v), y.px(d))
        })
        .collect();
    let _ = write!(
        out,
        "<polyline points=\"{}\" fill=\"none\" stroke=\"#c00\" stroke-dasharray=\"4 2\"/>",
        normal.join(" ")
    );
    for (k, s) in series.iter().enumerate() {
        let mut path = format!("M{:.1},{:.1}", x.px(low), y.px(0.0));
        for (b, d) in s.density.iter().enumerate() {
            let left = x.px(low + width * b as f64);
            let right = x.px(low + width * (b + 1) as f64);
            let top = y.px(*d);
            let _ = write!(path, " L{left:.1},{top:.1} L{right:.1},{top:.1}");
        }
        let _ = write!(path, " L{:.1},{:.1}", x.px(high), y.px(0.0));
        let _ = write!(
            out,
            "<path d=\"{path}\" fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\"/>\
             <text x=\"{}\" y=\"{}\" text-anchor=\"end\" fill=\"{}\">{}</text>",
            s.colour,
            WIDTH - RIGHT - 4.0,
            TOP + 12.0 + 12.0 * k as f64,
            s.colour,
            escape(s.name)
        );
    }
    let _ = write!(
        out,
        "<text x=\"{}\" y=\"{}\" fill=\"#c00\">N(0,1): tracker noise</text></svg>",
        LEFT + 4.0,
        TOP + 12.0
    );
    out
}

/// Horizontal bars `(label, value)`; missing values are shown as "–".
pub fn bars(title: &str, unit: &str, rows: &[(String, Option<f64>)]) -> String {
    let row_height = 20.0;
    let label_width = 250.0;
    let bar_width = 260.0;
    let height = TOP + row_height * rows.len() as f64 + 10.0;
    let width = label_width + bar_width + 70.0;
    let peak = rows
        .iter()
        .filter_map(|(_, v)| *v)
        .fold(0.0, f64::max)
        .max(1e-12);
    let mut out = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" \
         font-family=\"sans-serif\" font-size=\"11\"><text x=\"4\" y=\"14\">{}</text>",
        escape(title)
    );
    for (k, (label, value)) in rows.iter().enumerate() {
        let y = TOP + row_height * k as f64;
        let _ = write!(
            out,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            label_width - 6.0,
            y + 13.0,
            escape(label)
        );
        match value {
            Some(v) => {
                let w = bar_width * v / peak;
                let _ = write!(
                    out,
                    "<rect x=\"{label_width}\" y=\"{:.1}\" width=\"{w:.1}\" height=\"14\" fill=\"#4a7ebb\"/>\
                     <text x=\"{:.1}\" y=\"{:.1}\">{v:.3} {}</text>",
                    y + 2.0,
                    label_width + w + 4.0,
                    y + 13.0,
                    escape(unit)
                );
            }
            None => {
                let _ = write!(
                    out,
                    "<text x=\"{label_width}\" y=\"{:.1}\">–</text>",
                    y + 13.0
                );
            }
        }
    }
    out.push_str("</svg>");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_inside_the_range() {
        let axis = Axis::new(-0.37, 1.22, 0.0, 100.0);
        let ticks = axis.ticks();
        let expected = [0.0, 0.5, 1.0];
        assert_eq!(ticks.len(), expected.len(), "{ticks:?}");
        assert!(
            ticks
                .iter()
                .zip(expected)
                .all(|(a, b)| (a - b).abs() < 1e-12),
            "{ticks:?}"
        );
        assert!((axis.px(-0.37)).abs() < 1e-12 && (axis.px(1.22) - 100.0).abs() < 1e-12);
    }

    #[test]
    fn charts_are_single_svg_elements_with_escaped_text() {
        let line = [(0.0, 1.5), (1.0, 1.5)];
        let svg = Scatter {
            title: "a<b",
            x_label: "x",
            y_label: "y",
            points: &[(0.0, 1.0, 0), (1.0, 2.0, 1)],
            lines: &[(1, &line)],
            palette: &["#123", "#456"],
            x_range: (0.0, 1.0),
            y_range: (0.0, 2.0),
        }
        .render();
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>"));
        assert!(svg.contains("a&lt;b") && svg.matches("<circle").count() == 2);
        assert!(svg.contains("fill=\"#456\"") && svg.contains("<polyline"));
        let density = [0.1, 0.3, 0.1];
        let h = histogram(
            "h",
            "x",
            -1.5,
            1.0,
            &[DensitySeries {
                name: "s",
                colour: "#00f",
                density: &density,
            }],
        );
        assert!(h.contains("<path") && h.contains("N(0,1)"));
        let b = bars(
            "b",
            "mm",
            &[("one".into(), Some(2.0)), ("two".into(), None)],
        );
        assert_eq!(b.matches("<rect").count(), 1);
        assert!(b.contains("2.000 mm") && b.contains("–"));
    }
}

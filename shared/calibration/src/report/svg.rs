//! The SVG charts of the HTML report, drawn with `plotters` (SVG backend): scatter plots, a
//! histogram with the standard normal density, and horizontal bars. Each chart is a
//! self-contained `<svg>` element the report embeds inline.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Chart size (px).
const WIDTH: u32 = 320;
const HEIGHT: u32 = 220;
/// Font of titles and labels.
const FONT: &str = "sans-serif";
/// Colour of the reference normal density.
const NORMAL_COLOUR: RGBColor = RGBColor(0xcc, 0x00, 0x00);
/// Colour of the zero line.
const ZERO_COLOUR: RGBColor = RGBColor(0xcc, 0xcc, 0xcc);
/// Colour of the bars.
const BAR_COLOUR: RGBColor = RGBColor(0x4a, 0x7e, 0xbb);

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type Drawn = Result<(), DrawingAreaErrorKind<std::io::Error>>;

/// Renders one chart of `size` px to an SVG string. A chart that cannot be drawn becomes an
/// SVG saying so (with the reason), so a report never silently lacks a plot.
fn render(size: (u32, u32), draw: impl FnOnce(&Area<'_>) -> Drawn) -> String {
    let mut out = String::new();
    let drawn = {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        draw(&root).and_then(|()| root.present())
    };
    match drawn {
        Ok(()) => out.trim_end().to_owned(),
        Err(error) => {
            let reason = error
                .to_string()
                .replace('&', "&amp;")
                .replace('<', "&lt;")
                .replace('>', "&gt;");
            format!(
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"40\">\
                 <text x=\"4\" y=\"20\">chart not drawn: {reason}</text></svg>",
                size.0
            )
        }
    }
}

/// `#rgb` or `#rrggbb` as a colour; black for anything else.
fn colour(hex: &str) -> RGBColor {
    let digits = hex.trim_start_matches('#');
    let channel = |text: &str| u8::from_str_radix(text, 16).ok();
    let parsed = match digits.len() {
        3 => digits
            .chars()
            .map(|c| channel(&c.to_string()).map(|v| v * 17))
            .collect::<Option<Vec<u8>>>(),
        6 => (0..3)
            .map(|i| channel(&digits[2 * i..2 * i + 2]))
            .collect::<Option<Vec<u8>>>(),
        _ => None,
    };
    match parsed.as_deref() {
        Some(&[r, g, b]) => RGBColor(r, g, b),
        _ => BLACK,
    }
}

/// A non-empty range: `(low, high)`, or one unit either side of `low` when it is empty.
fn nonempty((low, high): (f64, f64)) -> (f64, f64) {
    if high > low {
        (low, high)
    } else {
        (low - 1.0, low + 1.0)
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

fn tick_label(value: &f64) -> String {
    let text = format!("{value:.3}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    match text {
        "-0" => "0".to_owned(),
        other => other.to_owned(),
    }
}

/// A chart with a title, axes with about five round ticks and their labels.
fn axes<'a, 'b>(
    root: &'a Area<'b>,
    title: &str,
    (x_label, y_label): (&str, &str),
    (x_low, x_high): (f64, f64),
    (y_low, y_high): (f64, f64),
) -> Result<
    ChartContext<
        'a,
        SVGBackend<'b>,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    DrawingAreaErrorKind<std::io::Error>,
> {
    let mut chart = ChartBuilder::on(root)
        .caption(title, (FONT, 11))
        .margin(6)
        .x_label_area_size(30)
        .y_label_area_size(46)
        .build_cartesian_2d(x_low..x_high, y_low..y_high)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(5)
        .y_labels(5)
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style((FONT, 10))
        .axis_desc_style((FONT, 10))
        .draw()?;
    Ok(chart)
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
    /// Colour of each class (`#rrggbb`).
    pub palette: &'a [&'a str],
    /// Horizontal range.
    pub x_range: (f64, f64),
    /// Vertical range (points beyond it are drawn at its edge).
    pub y_range: (f64, f64),
}

impl Scatter<'_> {
    /// The chart.
    pub fn render(&self) -> String {
        render((WIDTH, HEIGHT), |root| self.draw(root))
    }

    fn draw(&self, root: &Area<'_>) -> Drawn {
        let (x_low, x_high) = nonempty(self.x_range);
        let (y_low, y_high) = nonempty(self.y_range);
        let mut chart = axes(
            root,
            self.title,
            (self.x_label, self.y_label),
            (x_low, x_high),
            (y_low, y_high),
        )?;
        if (y_low..=y_high).contains(&0.0) {
            chart.draw_series(LineSeries::new([(x_low, 0.0), (x_high, 0.0)], ZERO_COLOUR))?;
        }
        let class_colour = |class: usize| self.palette.get(class).map_or(BLACK, |c| colour(c));
        chart.draw_series(self.points.iter().map(|&(x, y, class)| {
            Circle::new(
                (x, y.clamp(y_low, y_high)),
                1.4,
                class_colour(class).mix(0.45).filled(),
            )
        }))?;
        for (class, line) in self.lines {
            chart.draw_series(LineSeries::new(
                line.iter().map(|&(x, y)| (x, y.clamp(y_low, y_high))),
                class_colour(*class).stroke_width(2),
            ))?;
        }
        Ok(())
    }
}

/// A histogram series: densities per bin.
pub struct DensitySeries<'a> {
    /// Legend text.
    pub name: &'a str,
    /// Stroke colour (`#rrggbb`).
    pub colour: &'a str,
    /// Density of each bin.
    pub density: &'a [f64],
}

/// The outline of a step histogram over bins `low + k·width`.
fn steps(low: f64, width: f64, density: &[f64]) -> Vec<(f64, f64)> {
    let mut points = vec![(low, 0.0)];
    for (bin, &d) in density.iter().enumerate() {
        points.push((low + width * bin as f64, d));
        points.push((low + width * (bin + 1) as f64, d));
    }
    points.push((low + width * density.len() as f64, 0.0));
    points
}

/// A short legend line in `colour`.
fn legend_line(colour: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new([(x, y), (x + 14, y)], colour.stroke_width(2))
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
    render((WIDTH, HEIGHT), |root| {
        let (x_low, x_high) = nonempty((low, high));
        let mut chart = axes(
            root,
            title,
            (x_label, "density"),
            (x_low, x_high),
            (0.0, peak * 1.05),
        )?;
        let normal: Vec<(f64, f64)> = (0..=200)
            .map(|k| {
                let v = x_low + (x_high - x_low) * f64::from(k) / 200.0;
                (
                    v,
                    (-0.5 * v * v).exp() / (2.0 * std::f64::consts::PI).sqrt(),
                )
            })
            .collect();
        chart
            .draw_series(DashedLineSeries::new(normal, 4, 2, NORMAL_COLOUR.into()))?
            .label("N(0,1): tracker noise")
            .legend(legend_line(NORMAL_COLOUR));
        for s in series {
            let stroke = colour(s.colour);
            chart
                .draw_series(LineSeries::new(
                    steps(low, width, s.density),
                    stroke.stroke_width(2),
                ))?
                .label(s.name)
                .legend(legend_line(stroke));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FONT, 10))
            .background_style(WHITE.mix(0.8))
            .draw()
    })
}

/// Horizontal bars `(label, value)`; missing values are shown as "–".
pub fn bars(title: &str, unit: &str, rows: &[(String, Option<f64>)]) -> String {
    const ROW_HEIGHT: i32 = 20;
    const TOP: i32 = 24;
    const LABEL_WIDTH: i32 = 250;
    const BAR_WIDTH: f64 = 260.0;
    let height = TOP + ROW_HEIGHT * rows.len() as i32 + 10;
    let width = LABEL_WIDTH + BAR_WIDTH as i32 + 70;
    let peak = rows
        .iter()
        .filter_map(|(_, v)| *v)
        .fold(0.0, f64::max)
        .max(1e-12);
    render((width as u32, height as u32), |root| {
        let left = TextStyle::from((FONT, 11)).pos(Pos::new(HPos::Left, VPos::Center));
        let right = TextStyle::from((FONT, 11)).pos(Pos::new(HPos::Right, VPos::Center));
        root.draw(&Text::new(title.to_owned(), (4, 10), left.clone()))?;
        for (k, (label, value)) in rows.iter().enumerate() {
            let middle = TOP + ROW_HEIGHT * k as i32 + 9;
            root.draw(&Text::new(
                label.clone(),
                (LABEL_WIDTH - 6, middle),
                right.clone(),
            ))?;
            match value {
                Some(v) => {
                    let w = (BAR_WIDTH * v / peak).round() as i32;
                    root.draw(&Rectangle::new(
                        [(LABEL_WIDTH, middle - 7), (LABEL_WIDTH + w, middle + 7)],
                        BAR_COLOUR.filled(),
                    ))?;
                    root.draw(&Text::new(
                        format!("{v:.3} {unit}"),
                        (LABEL_WIDTH + w + 4, middle),
                        left.clone(),
                    ))?;
                }
                None => root.draw(&Text::new("–", (LABEL_WIDTH, middle), left.clone()))?,
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_ranges_and_tick_labels() {
        assert_eq!(colour("#4a7ebb"), RGBColor(0x4a, 0x7e, 0xbb));
        assert_eq!(colour("#123"), RGBColor(0x11, 0x22, 0x33));
        assert_eq!(colour("blue"), BLACK);
        assert_eq!(nonempty((2.0, 2.0)), (1.0, 3.0));
        assert_eq!(padded_range([0.0, 10.0].into_iter()), (-0.5, 10.5));
        assert_eq!(padded_range(std::iter::empty()), (-1.0, 1.0));
        assert_eq!(tick_label(&0.5), "0.5");
        assert_eq!(tick_label(&-0.0001), "0");
        assert_eq!(tick_label(&12.0), "12");
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
        assert!(svg.contains("#445566") && svg.contains("<polyline"));
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
        assert!(h.starts_with("<svg") && h.ends_with("</svg>"));
        assert!(h.contains("<polyline") && h.contains("N(0,1)") && h.contains("#0000FF"));
        let b = bars(
            "b",
            "mm",
            &[("one".into(), Some(2.0)), ("two".into(), None)],
        );
        assert_eq!(b.matches("<rect").count(), 1);
        assert!(b.contains("2.000 mm") && b.contains("–"));
    }
}

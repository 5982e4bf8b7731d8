//! Line plots as PNG, for measurements the tool reports (`probegi lag`): axes with
//! tick labels, one polyline with markers per series, optional horizontal guide
//! lines and a legend. Text uses a built-in 3×5 pixel font (upper case, digits and
//! a little punctuation), so no font file or plotting crate is needed.

use std::path::Path;

use crate::io::ImageError;

/// One curve.
#[derive(Clone, Debug)]
pub struct Series {
    /// Its name in the legend.
    pub label: String,
    /// Line and marker colour (see [`PALETTE`]).
    pub rgb: [u8; 3],
    /// Data points `(x, y)`, joined in order.
    pub points: Vec<(f64, f64)>,
    /// Draw as a dashed line.
    pub dashed: bool,
}

/// A line plot: title, axis labels, curves and guide lines.
#[derive(Clone, Debug, Default)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// The curves, in legend order.
    pub series: Vec<Series>,
    /// Horizontal guide lines `(y, label)`.
    pub guides: Vec<(f64, String)>,
}

const W: usize = 900;
const H: usize = 520;
const LEFT: usize = 80;
const RIGHT: usize = 270;
const TOP: usize = 50;
const BOTTOM: usize = 60;
const TEXT_SCALE: usize = 2;

/// 3×5 glyphs, rows top to bottom, 3 bits per row (MSB = left column).
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 3, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        '-' => [0, 0, 7, 0, 0],
        '=' => [0, 7, 0, 7, 0],
        ':' => [0, 2, 0, 2, 0],
        '(' => [2, 4, 4, 4, 2],
        ')' => [2, 1, 1, 1, 2],
        '/' => [1, 1, 2, 4, 4],
        '%' => [5, 1, 2, 4, 5],
        '>' => [4, 2, 1, 2, 4],
        '<' => [1, 2, 4, 2, 1],
        _ => [0; 5],
    }
}

struct Canvas {
    rgb: Vec<u8>,
}

impl Canvas {
    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < W && (y as usize) < H {
            let i = (y as usize * W + x as usize) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    fn dot(&mut self, x: i64, y: i64, r: i64, c: [u8; 3]) {
        for dy in -r..=r {
            for dx in -r..=r {
                self.set(x + dx, y + dy, c);
            }
        }
    }

    /// A 2-pixel-wide line; `dashed` skips every other 6-pixel run.
    fn line(&mut self, (x0, y0): (f64, f64), (x1, y1): (f64, f64), c: [u8; 3], dashed: bool) {
        let n = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
        for i in 0..=n {
            if dashed && (i / 6) % 2 == 1 {
                continue;
            }
            let t = i as f64 / n as f64;
            let (x, y) = (x0 + (x1 - x0) * t, y0 + (y1 - y0) * t);
            self.dot(x.round() as i64, y.round() as i64, 1, c);
        }
    }

    fn text(&mut self, x: usize, y: usize, s: &str, c: [u8; 3]) {
        for (k, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        for sy in 0..TEXT_SCALE {
                            for sx in 0..TEXT_SCALE {
                                let px = x + (k * 4 + col) * TEXT_SCALE + sx;
                                self.set(px as i64, (y + row * TEXT_SCALE + sy) as i64, c);
                            }
                        }
                    }
                }
            }
        }
    }
}

fn text_width(s: &str) -> usize {
    s.chars().count() * 4 * TEXT_SCALE
}

/// A "nice" tick step (1, 2 or 5 × 10ᵏ) giving about `n` ticks over `range`.
fn tick_step(range: f64, n: f64) -> f64 {
    let raw = (range / n).max(1e-12);
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p)
}

fn fmt_tick(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 { 0 } else { (-step.log10().floor()) as usize };
    format!("{v:.decimals$}")
}

impl LinePlot {
    /// Renders to 8-bit RGB, `W × H`.
    pub fn render_rgb8(&self) -> (u32, u32, Vec<u8>) {
        let mut cv = Canvas { rgb: vec![255; W * H * 3] };
        let pts = self.series.iter().flat_map(|s| s.points.iter().copied());
        let finite: Vec<(f64, f64)> = pts.filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
        let (mut x0, mut x1) = finite.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
        let mut y1 = finite.iter().fold(f64::MIN, |a, p| a.max(p.1));
        y1 = self.guides.iter().fold(y1, |a, g| a.max(g.0));
        if finite.is_empty() {
            (x0, x1, y1) = (0.0, 1.0, 1.0);
        }
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let y0 = 0.0;
        let ystep = tick_step(y1.max(1e-9) - y0, 6.0);
        let y1 = ((y1 / ystep).ceil() * ystep).max(ystep);
        let (pw, ph) = ((W - LEFT - RIGHT) as f64, (H - TOP - BOTTOM) as f64);
        let to_px =
            |x: f64, y: f64| (LEFT as f64 + (x - x0) / (x1 - x0) * pw, (H - BOTTOM) as f64 - (y - y0) / (y1 - y0) * ph);
        let grey = [200, 200, 200];
        let black = [20, 20, 20];
        // Grid and ticks.
        let mut y = y0;
        while y <= y1 + ystep * 0.01 {
            let (_, py) = to_px(x0, y);
            cv.line((LEFT as f64, py), ((W - RIGHT) as f64, py), grey, false);
            let label = fmt_tick(y, ystep);
            cv.text(LEFT - 8 - text_width(&label), py as usize - 5, &label, black);
            y += ystep;
        }
        let xstep = tick_step(x1 - x0, 8.0);
        let mut x = (x0 / xstep).ceil() * xstep;
        while x <= x1 + xstep * 0.01 {
            let (px, _) = to_px(x, y0);
            cv.line((px, (H - BOTTOM) as f64), (px, (H - BOTTOM + 6) as f64), black, false);
            let label = fmt_tick(x, xstep);
            cv.text(px as usize - text_width(&label) / 2, H - BOTTOM + 12, &label, black);
            x += xstep;
        }
        cv.line((LEFT as f64, TOP as f64), (LEFT as f64, (H - BOTTOM) as f64), black, false);
        cv.line((LEFT as f64, (H - BOTTOM) as f64), ((W - RIGHT) as f64, (H - BOTTOM) as f64), black, false);
        for (gy, label) in &self.guides {
            let (_, py) = to_px(x0, *gy);
            cv.line((LEFT as f64, py), ((W - RIGHT) as f64, py), [120, 120, 120], true);
            cv.text(W - RIGHT - text_width(label) - 4, py as usize - 14, label, [90, 90, 90]);
        }
        for s in &self.series {
            let p: Vec<(f64, f64)> =
                s.points.iter().filter(|(x, y)| x.is_finite() && y.is_finite()).map(|&(x, y)| to_px(x, y)).collect();
            for w in p.windows(2) {
                cv.line(w[0], w[1], s.rgb, s.dashed);
            }
            if p.len() <= 40 {
                for &(x, y) in &p {
                    cv.dot(x.round() as i64, y.round() as i64, 3, s.rgb);
                }
            }
        }
        // Labels and legend.
        cv.text((W - RIGHT + LEFT) / 2 - text_width(&self.title) / 2, 16, &self.title, black);
        cv.text((W - RIGHT + LEFT) / 2 - text_width(&self.x_label) / 2, H - 24, &self.x_label, black);
        cv.text(8, TOP - 24, &self.y_label, black);
        for (k, s) in self.series.iter().enumerate() {
            let y = TOP + 10 + k * 22;
            let x = W - RIGHT + 16;
            cv.line((x as f64, y as f64 + 5.0), (x as f64 + 28.0, y as f64 + 5.0), s.rgb, s.dashed);
            cv.text(x + 36, y, &s.label, black);
        }
        (W as u32, H as u32, cv.rgb)
    }

    /// Draws the plot and writes it as a PNG to `path`.
    pub fn write_png(&self, path: &Path) -> Result<(), ImageError> {
        let (w, h, rgb) = self.render_rgb8();
        crate::io::write_png(path, w, h, rgb)
    }
}

/// Distinct colours for up to 10 series (Tableau 10).
pub const PALETTE: [[u8; 3]; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_land_where_their_values_say() {
        let plot = LinePlot {
            title: "T".into(),
            series: vec![Series {
                label: "A".into(),
                rgb: [255, 0, 0],
                points: vec![(0.0, 0.0), (10.0, 1.0)],
                dashed: false,
            }],
            ..Default::default()
        };
        let (w, _, rgb) = plot.render_rgb8();
        let red = |x: usize, y: usize| {
            let i = (y * w as usize + x) * 3;
            rgb[i] > 200 && rgb[i + 1] < 80
        };
        // The line runs from the bottom-left to the top-right corner of the plot area.
        assert!(red(LEFT, H - BOTTOM) && red(W - RIGHT, TOP));
        let (mx, my) = ((LEFT + W - RIGHT) / 2, (TOP + H - BOTTOM) / 2);
        assert!((0..4).any(|d| red(mx, my - 2 + d)), "midpoint on the line");
        assert!(!red(LEFT + 5, TOP + 5));
    }

    #[test]
    fn ticks_are_round_numbers() {
        assert_eq!(tick_step(1.0, 5.0), 0.2);
        assert_eq!(tick_step(150.0, 8.0), 20.0);
        assert_eq!(fmt_tick(0.05, 0.01), "0.05");
    }
}

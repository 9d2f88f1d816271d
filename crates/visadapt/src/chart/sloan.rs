//! Sloan optotypes: the ten letters C D H K N O R S V Z of the chart, and its E.
//!
//! Louise Sloan (1959, "New test charts for the measurement of visual acuity at far and
//! near distances", Am. J. Ophthalmol. 48:807) drew ten sans-serif letters on a square of
//! five stroke widths; the NAS-NRC Committee on Vision's recommended standard (1980,
//! "Recommended standard procedures for the clinical measurement and specification of
//! visual acuity", Adv. Ophthalmol. 41:103) adopted them: letter height = width = 5 stroke
//! widths, the stroke a fifth of the height, "round" where the letters are round. These
//! are the rules followed here; the outlines within them are our construction, in units of
//! one stroke width on the 5 × 5 square (`u` to the right, `v` down, origin top-left):
//!
//! * **round strokes** are circular rings one stroke wide: O is the ring of outer radius
//!   2.5 around the centre; C the same ring with a gap one stroke wide on the right; D a
//!   stem, two bars and the right half of that ring; R and S use half rings of outer
//!   radius 1.5 (the bowl of R; the two bowls of S, joined by three bars);
//! * **straight strokes** are bars (H, the stems, the bars of Z and E) and slanted
//!   strokes with horizontal ends whose width *across* the stroke is one (N, Z, K, the
//!   leg of R; V is one polygon with a flat point one stroke wide).
//!
//! The shapes of a letter do not overlap, so its ink area is the sum of their areas
//! (tested against those areas computed independently). Pixels are covered by area: each
//! pixel is the fraction of [`SAMPLES`]² regularly spaced points in it that fall on ink,
//! exact for edges on pixel boundaries.

/// Points per pixel side sampled for the area coverage (256 per pixel: coverage to 1/256,
/// exact for the straight edges the chart aligns to pixels).
pub const SAMPLES: usize = 16;

/// One shape of a letter, in stroke widths on the 5 × 5 square.
#[derive(Debug, Clone, PartialEq)]
enum Shape {
    /// `[u0, v0, u1, v1]`.
    Rect([f64; 4]),
    /// A ring around `centre`, radii `inner..outer`, restricted to `part`.
    Ring {
        centre: (f64, f64),
        inner: f64,
        outer: f64,
        part: Part,
    },
    /// A simple polygon (vertices in order).
    Polygon(Vec<(f64, f64)>),
}

/// Which part of a ring a shape keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    Whole,
    /// `u ≥ centre`.
    Right,
    /// `u ≤ centre`.
    Left,
    /// The whole ring but the band one stroke high on the right (the C's gap).
    OpenRight,
}

impl Shape {
    fn contains(&self, u: f64, v: f64) -> bool {
        match self {
            Shape::Rect([u0, v0, u1, v1]) => (*u0..*u1).contains(&u) && (*v0..*v1).contains(&v),
            Shape::Ring {
                centre: (cu, cv),
                inner,
                outer,
                part,
            } => {
                let (du, dv) = (u - cu, v - cv);
                let r2 = du * du + dv * dv;
                let in_ring = r2 >= inner * inner && r2 < outer * outer;
                in_ring
                    && match part {
                        Part::Whole => true,
                        Part::Right => du >= 0.0,
                        Part::Left => du <= 0.0,
                        Part::OpenRight => !(du > 0.0 && dv.abs() < 0.5),
                    }
            }
            Shape::Polygon(p) => {
                // Even-odd rule: a ray to the right crosses the outline an odd number of times.
                let mut inside = false;
                for k in 0..p.len() {
                    let (a, b) = (p[k], p[(k + 1) % p.len()]);
                    if (a.1 > v) != (b.1 > v) && u < a.0 + (v - a.1) / (b.1 - a.1) * (b.0 - a.0) {
                        inside = !inside;
                    }
                }
                inside
            }
        }
    }
}

/// The horizontal width `h` of a slanted stroke with horizontal ends `dy` apart, whose
/// left edge runs `dx(h)` across: the stroke is one wide across its direction,
/// `h·dy / √(dx² + dy²) = 1` (a fixed point, reached to 1e-15 in a few dozen steps since
/// `|dx'| ≤ 1`).
fn slant_width(dx: impl Fn(f64) -> f64, dy: f64) -> f64 {
    let mut h = 1.0;
    for _ in 0..200 {
        h = dx(h).hypot(dy) / dy;
    }
    h
}

/// A letter's shapes; `None` for a letter the chart does not have.
fn shapes(letter: char) -> Option<Vec<Shape>> {
    use Shape::{Polygon, Rect, Ring};
    let ring = |centre, inner, outer, part| Ring {
        centre,
        inner,
        outer,
        part,
    };
    Some(match letter {
        'C' => vec![ring((2.5, 2.5), 1.5, 2.5, Part::OpenRight)],
        'O' => vec![ring((2.5, 2.5), 1.5, 2.5, Part::Whole)],
        'D' => vec![
            Rect([0.0, 0.0, 1.0, 5.0]),
            Rect([1.0, 0.0, 2.5, 1.0]),
            Rect([1.0, 4.0, 2.5, 5.0]),
            ring((2.5, 2.5), 1.5, 2.5, Part::Right),
        ],
        'E' => vec![
            Rect([0.0, 0.0, 1.0, 5.0]),
            Rect([1.0, 0.0, 5.0, 1.0]),
            Rect([1.0, 2.0, 5.0, 3.0]),
            Rect([1.0, 4.0, 5.0, 5.0]),
        ],
        'H' => vec![
            Rect([0.0, 0.0, 1.0, 5.0]),
            Rect([4.0, 0.0, 5.0, 5.0]),
            Rect([1.0, 2.0, 4.0, 3.0]),
        ],
        'K' => {
            // Arm and leg meet the stem at mid-height, each 2.5 high.
            let h = slant_width(|h| 4.0 - h, 2.5);
            vec![
                Rect([0.0, 0.0, 1.0, 5.0]),
                Polygon(vec![(5.0 - h, 0.0), (5.0, 0.0), (1.0 + h, 2.5), (1.0, 2.5)]),
                Polygon(vec![(1.0, 2.5), (1.0 + h, 2.5), (5.0, 5.0), (5.0 - h, 5.0)]),
            ]
        }
        'N' => {
            let h = slant_width(|h| 3.0 - h, 5.0);
            vec![
                Rect([0.0, 0.0, 1.0, 5.0]),
                Rect([4.0, 0.0, 5.0, 5.0]),
                Polygon(vec![(1.0, 0.0), (1.0 + h, 0.0), (4.0, 5.0), (4.0 - h, 5.0)]),
            ]
        }
        'R' => {
            let h = slant_width(|h| 2.5 - h, 2.0);
            vec![
                Rect([0.0, 0.0, 1.0, 5.0]),
                Rect([1.0, 0.0, 3.5, 1.0]),
                Rect([1.0, 2.0, 3.5, 3.0]),
                ring((3.5, 1.5), 0.5, 1.5, Part::Right),
                Polygon(vec![(2.5, 3.0), (2.5 + h, 3.0), (5.0, 5.0), (5.0 - h, 5.0)]),
            ]
        }
        'S' => vec![
            Rect([1.5, 0.0, 5.0, 1.0]),
            ring((1.5, 1.5), 0.5, 1.5, Part::Left),
            Rect([1.5, 2.0, 3.5, 3.0]),
            ring((3.5, 3.5), 0.5, 1.5, Part::Right),
            Rect([0.0, 4.0, 3.5, 5.0]),
        ],
        'V' => {
            // Outer edges from the top corners to a flat point one stroke wide; inner
            // edges parallel, one stroke in.
            let h = 29f64.sqrt() / 5.0;
            let apex = 2.5 * (2.5 - h);
            vec![Polygon(vec![
                (0.0, 0.0),
                (h, 0.0),
                (2.5, apex),
                (5.0 - h, 0.0),
                (5.0, 0.0),
                (3.0, 5.0),
                (2.0, 5.0),
            ])]
        }
        'Z' => {
            let h = slant_width(|h| 5.0 - h, 3.0);
            vec![
                Rect([0.0, 0.0, 5.0, 1.0]),
                Rect([0.0, 4.0, 5.0, 5.0]),
                Polygon(vec![(5.0 - h, 1.0), (5.0, 1.0), (h, 4.0), (0.0, 4.0)]),
            ]
        }
        _ => return None,
    })
}

/// A letter ready to be drawn: its shapes.
#[derive(Debug, Clone, PartialEq)]
pub struct Optotype {
    shapes: Vec<Shape>,
}

impl Optotype {
    /// The letter, `None` for one the chart does not have (it has C D E H K N O R S V Z).
    pub fn new(letter: char) -> Option<Self> {
        shapes(letter).map(|shapes| Optotype { shapes })
    }

    /// Whether the point `(u, v)` of the 5 × 5 square (stroke widths) is ink.
    pub fn is_ink(&self, u: f64, v: f64) -> bool {
        self.shapes.iter().any(|s| s.contains(u, v))
    }

    /// The fraction of pixel `(i, j)` covered by ink, for a letter whose square has its
    /// top-left corner at `(x, y)` pixels and a stroke width of `stroke_px` pixels.
    pub fn coverage(&self, i: usize, j: usize, x: f64, y: f64, stroke_px: f64) -> f64 {
        let n = SAMPLES as f64;
        let mut ink = 0usize;
        for b in 0..SAMPLES {
            let v = (j as f64 + (b as f64 + 0.5) / n - y) / stroke_px;
            for a in 0..SAMPLES {
                let u = (i as f64 + (a as f64 + 0.5) / n - x) / stroke_px;
                ink += usize::from(self.is_ink(u, v));
            }
        }
        ink as f64 / (n * n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The positive root of `a·h² + b·h + c = 0`.
    fn root(a: f64, b: f64, c: f64) -> f64 {
        (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a)
    }

    /// Each letter's ink area in square stroke widths, from its construction (module docs)
    /// worked out by hand: rings `π(R² − r²)`, bars, slanted strokes `h·dy` with `h` from
    /// `h·dy = √((dx(h))² + dy²)` squared into a quadratic.
    fn analytic_area(letter: char) -> f64 {
        let ring = PI * (2.5f64.powi(2) - 1.5f64.powi(2));
        let small_ring = PI * (1.5f64.powi(2) - 0.5f64.powi(2));
        // ∫ √(a² − y²) dy over |y| ≤ 0.5.
        let band = |a: f64| 0.5 * (a * a - 0.25f64).sqrt() + a * a * (0.5 / a).asin();
        match letter {
            'C' => ring - (band(2.5) - band(1.5)),
            'O' => ring,
            'D' => 5.0 + 1.5 + 1.5 + ring / 2.0,
            'E' => 5.0 + 3.0 * 4.0,
            'H' => 13.0,
            // 6.25 h² = (4 − h)² + 6.25
            'K' => 5.0 + 2.0 * 2.5 * root(5.25, 8.0, -22.25),
            // 25 h² = (3 − h)² + 25
            'N' => 10.0 + 5.0 * root(24.0, 6.0, -34.0),
            // 4 h² = (2.5 − h)² + 4
            'R' => 5.0 + 2.5 + 2.5 + small_ring / 2.0 + 2.0 * root(3.0, 5.0, -10.25),
            'S' => 3.5 + 2.0 + 3.5 + small_ring,
            'V' => {
                // The trapezoid of the outer edges less the notch between the inner ones.
                let h = 29f64.sqrt() / 5.0;
                15.0 - (5.0 - 2.0 * h) * 2.5 * (2.5 - h) / 2.0
            }
            // 9 h² = (5 − h)² + 9
            'Z' => 10.0 + 3.0 * root(8.0, 10.0, -34.0),
            _ => unreachable!(),
        }
    }

    const LETTERS: [char; 11] = ['C', 'D', 'E', 'H', 'K', 'N', 'O', 'R', 'S', 'V', 'Z'];

    /// A letter rasterised at `stroke_px` pixels per stroke, its square at (x, y).
    fn raster(letter: char, x: f64, y: f64, stroke_px: f64) -> (Vec<f64>, usize) {
        let o = Optotype::new(letter).unwrap();
        let n = (x + 5.0 * stroke_px).ceil() as usize + 1;
        let mut v = vec![0.0; n * n];
        for j in 0..n {
            for i in 0..n {
                v[j * n + i] = o.coverage(i, j, x, y, stroke_px);
            }
        }
        (v, n)
    }

    /// The rasterised ink, off the pixel grid, against the construction's area: within
    /// 1e-3 of the letter's square (sampling error along the edges).
    #[test]
    fn ink_fractions_match_the_construction() {
        for letter in LETTERS {
            let (v, _) = raster(letter, 0.37, 0.61, 20.0);
            let fraction = v.iter().sum::<f64>() / (100.0 * 100.0);
            let expected = analytic_area(letter) / 25.0;
            assert!(
                (fraction - expected).abs() < 1e-3,
                "{letter}: {fraction} against {expected}"
            );
        }
        // The values: O 0.503, C 0.463, H 0.52, S 0.611, V 0.46 ...
        assert!((analytic_area('O') / 25.0 - 0.502_65).abs() < 1e-5);
        assert!((analytic_area('H') / 25.0 - 0.52).abs() < 1e-12);
    }

    /// The slanted strokes are one stroke wide across their direction.
    #[test]
    fn slanted_strokes_are_one_stroke_wide() {
        for (dx, dy) in [(4.0, 2.5), (3.0, 5.0), (2.5, 2.0), (5.0, 3.0)] {
            let h = slant_width(|h| dx - h, dy);
            let across = h * dy / (dx - h).hypot(dy);
            assert!((across - 1.0).abs() < 1e-12, "{dx}, {dy}: {across}");
        }
    }

    /// Every letter fills its 5 × 5 square (its height is the letter height the chart
    /// scales to 5 arcmin at 20/20), and the letters are distinct: any two differ on at
    /// least 3 % of the square (the closest pair is C and O, which differ by the C's gap
    /// alone, 4 %: the feature the observer must resolve, as with a Landolt ring).
    #[test]
    fn letters_fill_their_square_and_are_distinct() {
        let rasters: Vec<(char, Vec<f64>)> = LETTERS
            .iter()
            .map(|&l| (l, raster(l, 0.0, 0.0, 10.0).0))
            .collect();
        for (letter, v) in &rasters {
            let n = 51;
            let inked = |i: usize, j: usize| v[j * n + i] > 0.0;
            let rows: Vec<usize> = (0..n).filter(|&j| (0..n).any(|i| inked(i, j))).collect();
            let cols: Vec<usize> = (0..n).filter(|&i| (0..n).any(|j| inked(i, j))).collect();
            assert_eq!(
                (
                    rows[0],
                    *rows.last().unwrap(),
                    cols[0],
                    *cols.last().unwrap()
                ),
                (0, 49, 0, 49),
                "{letter}"
            );
        }
        for (a, (la, va)) in rasters.iter().enumerate() {
            for (lb, vb) in &rasters[a + 1..] {
                let differ: f64 = va.iter().zip(vb).map(|(x, y)| (x - y).abs()).sum();
                assert!(differ > 0.03 * 2500.0, "{la} and {lb}: {differ}");
            }
        }
        assert!(Optotype::new('A').is_none());
    }
}

//! Numbers for people in the text reports (the JSON reports keep every digit).
//!
//! The rule, one for every text report: four significant digits (`sig` takes another
//! count), trailing zeros dropped, a decimal point and no thousands separators (so that a
//! figure can be pasted into a shell, a spreadsheet or a script whatever its locale), and
//! plain decimals from 0.001 up to a million: `1841 cd/m²`, `0.02512`, `149.3`. Outside
//! that range, where plain digits would be a row of zeros, an exponent: `3.162e-5`, `2.5e7`.

use std::fmt;

/// Significant digits of the text reports.
pub const DIGITS: usize = 4;

/// Smallest magnitude written without an exponent.
const PLAIN_MIN: f64 = 1e-3;
/// Magnitudes from here up are written with an exponent.
const PLAIN_MAX: f64 = 1e6;

/// A number shown to `digits` significant digits (see the module's rule). Implements
/// `Display`, padding included (`{:>11}` aligns table columns).
#[derive(Clone, Copy, Debug)]
pub struct Num {
    value: f64,
    digits: usize,
}

/// `x` to four significant digits.
pub fn num(x: impl Into<f64>) -> Num {
    sig(x, DIGITS)
}

/// `x` to `digits` significant digits (at least one).
pub fn sig(x: impl Into<f64>, digits: usize) -> Num {
    Num {
        value: x.into(),
        digits: digits.max(1),
    }
}

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(&text(self.value, self.digits))
    }
}

fn text(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".to_string();
    }
    // Rounded first, so that 999.96 becomes 1000 and 0.00099996 becomes 0.001.
    let rounded: f64 = format!("{x:.prec$e}", prec = digits - 1)
        .parse()
        .expect("a formatted float parses");
    let magnitude = rounded.abs().log10().floor();
    if (PLAIN_MIN..PLAIN_MAX).contains(&rounded.abs()) {
        let decimals = (digits as f64 - 1.0 - magnitude).max(0.0) as usize;
        trim(&format!("{rounded:.decimals$}"))
    } else {
        let s = format!("{rounded:.prec$e}", prec = digits - 1);
        match s.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim(mantissa)),
            None => s,
        }
    }
}

/// Trailing zeros after a decimal point, and the point itself when nothing follows it.
fn trim(s: &str) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s.to_string()
    }
}

/// A count with its noun, singular for one: `1 panel`, `2 panels`, `0 panels`.
pub fn count(n: usize, singular: &str, plural: &str) -> String {
    format!("{n} {}", if n == 1 { singular } else { plural })
}

#[cfg(test)]
mod tests {
    use super::{count, num, sig};

    #[test]
    fn four_significant_digits_without_exponent_in_the_plain_range() {
        for (x, s) in [
            (1841.2, "1841"),
            (1.8412e3, "1841"),
            (5.0, "5"),
            (50.0, "50"),
            (149.29, "149.3"),
            (0.025119, "0.02512"),
            (0.001, "0.001"),
            (999_999.0, "1e6"),
            (123_456.0, "123500"),
            (999.96, "1000"),
            (0.000_999_96, "0.001"),
            (-12.5, "-12.5"),
            (0.0, "0"),
            (-0.0, "0"),
        ] {
            assert_eq!(num(x).to_string(), s, "{x}");
        }
    }

    #[test]
    fn an_exponent_only_far_from_one() {
        assert_eq!(num(3.16227e-5).to_string(), "3.162e-5");
        assert_eq!(num(9.916e-4).to_string(), "9.916e-4");
        assert_eq!(num(2.5e7).to_string(), "2.5e7");
        assert_eq!(num(1e19).to_string(), "1e19");
        assert_eq!(num(f64::NAN).to_string(), "NaN");
        assert_eq!(num(f64::INFINITY).to_string(), "inf");
    }

    #[test]
    fn other_digit_counts_and_padding() {
        assert_eq!(sig(0.0200, 3).to_string(), "0.02");
        assert_eq!(sig(2.2608, 3).to_string(), "2.26");
        assert_eq!(sig(0.5, 0).to_string(), "0.5");
        assert_eq!(format!("{:>8}|", num(0.5)), "     0.5|");
        assert_eq!(format!("{:<6}|", num(12.0)), "12    |");
    }

    #[test]
    fn counts_agree_with_their_noun() {
        assert_eq!(count(1, "panel", "panels"), "1 panel");
        assert_eq!(count(0, "panel", "panels"), "0 panels");
        assert_eq!(count(4, "pixel", "pixels"), "4 pixels");
    }
}

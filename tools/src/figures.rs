//! Figures as people read them: rounded to their resolution before they are printed or written
//! to JSON (`641.795`, not `641.7945556640625`; `0.719`, not `0.7190000000000001`).
//!
//! Every command's JSON and terminal figures go through these two functions, so a figure's
//! resolution is chosen where the figure is made (mm for distances, 0.1 l for air, 1 ms for
//! times, 1e-4 for ratios, a few significant digits for fitted parameters).

/// `x` rounded to `decimals` decimal places, as the f64 nearest to that decimal, so that JSON
/// (serde_json's shortest round-trip form) prints exactly the rounded decimal. A figure that
/// rounds to zero is +0 (`0.0`, never `-0.0`: Rust's f64 sum of nothing is -0.0, and so is a
/// tiny negative rounded). Non-finite values are returned unchanged.
pub fn round_dp(x: f64, decimals: u32) -> f64 {
    if !x.is_finite() {
        return x;
    }
    // Adding +0 turns -0 into +0 and leaves every other value as it is.
    format!("{x:.*}", decimals as usize)
        .parse::<f64>()
        .map_or(x, |r| r + 0.0)
}

/// `x` rounded to `digits` significant digits (fitted parameters, ratios of unknown size).
/// Zero is +0, non-finite values are returned unchanged; `digits` of 0 is taken as 1.
pub fn round_sig(x: f64, digits: u32) -> f64 {
    if !x.is_finite() {
        return x;
    }
    if x == 0.0 {
        return 0.0;
    }
    let magnitude = x.abs().log10().floor() as i32;
    let decimals = digits.max(1) as i32 - 1 - magnitude;
    if decimals >= 0 {
        round_dp(x, decimals as u32)
    } else {
        let unit = 10f64.powi(-decimals);
        (x / unit).round() * unit
    }
}

/// A list for people: `none`, `2`, `2 and 4`, `1, 2 and 4` (never a Rust debug form).
pub fn list_text<T: std::fmt::Display>(items: &[T]) -> String {
    match items {
        [] => "none".to_string(),
        [one] => one.to_string(),
        [init @ .., last] => {
            let init: Vec<String> = init.iter().map(|x| x.to_string()).collect();
            format!("{} and {last}", init.join(", "))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_prints_the_rounded_decimal() {
        let v = 641.7945556640625_f64;
        assert_eq!(serde_json::to_string(&round_dp(v, 3)).unwrap(), "641.795");
        assert_eq!(
            serde_json::to_string(&round_dp(0.7190000000000001, 4)).unwrap(),
            "0.719"
        );
        assert_eq!(
            serde_json::to_string(&round_dp(2.77 * 1.0000000000000002, 1)).unwrap(),
            "2.8"
        );
    }

    #[test]
    fn significant_digits_at_every_magnitude() {
        assert_eq!(round_sig(0.184_437_7, 4), 0.1844);
        assert_eq!(round_sig(-0.013_749, 3), -0.0137);
        assert_eq!(round_sig(355_345.2, 4), 355_300.0);
        assert_eq!(round_sig(0.0, 4), 0.0);
        assert!(round_sig(f64::NAN, 4).is_nan());
        assert_eq!(round_dp(f64::INFINITY, 3), f64::INFINITY);
    }

    #[test]
    fn zero_is_never_negative() {
        let nothing: f64 = std::iter::empty::<f64>().sum();
        for x in [nothing, -0.0, -1e-9, -0.04] {
            let r = round_dp(x, 1);
            assert!(r == 0.0 && r.is_sign_positive(), "{x} -> {r}");
            assert_eq!(serde_json::to_string(&r).unwrap(), "0.0");
            assert_eq!(format!("{r:.1}"), "0.0");
        }
        assert_eq!(round_dp(-0.06, 1), -0.1);
        assert!(round_sig(-0.0, 3).is_sign_positive());
    }

    #[test]
    fn lists_read_as_text() {
        assert_eq!(list_text::<u8>(&[]), "none");
        assert_eq!(list_text(&[2]), "2");
        assert_eq!(list_text(&[2, 4]), "2 and 4");
        assert_eq!(list_text(&["1", "2", "4"]), "1, 2 and 4");
    }
}

//! Numbers for the JSON outputs, written with a fixed number of decimals.
//!
//! serde_json builds every JSON object the CLI prints; only the digits of a figure are chosen here.
//! The figures are model estimates whose meaningful precision is known (a shaded fraction to six
//! places, a radius to a thousandth of a degree), and scripts compare the printed text: a float
//! printed shortest-round-trip would show noise digits (`0.8260113...`) and drop trailing zeros that
//! the output has always had (`1.000000`).

use serde::{Serialize, Serializer};
use serde_json::value::RawValue;

/// `value` with `DECIMALS` digits after the point; `null` if it is not finite (JSON has no NaN).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fixed<const DECIMALS: usize>(pub f64);

impl<const DECIMALS: usize> Serialize for Fixed<DECIMALS> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if !self.0.is_finite() {
            return s.serialize_none();
        }
        let text = format!("{:.*}", DECIMALS, self.0);
        let raw = RawValue::from_string(text).map_err(serde::ser::Error::custom)?;
        raw.serialize(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_decimals_and_null() {
        let v = (Fixed::<6>(1.0), Fixed::<3>(45.44712), Fixed::<4>(-0.5));
        assert_eq!(
            serde_json::to_string(&v).unwrap(),
            "[1.000000,45.447,-0.5000]"
        );
        assert_eq!(
            serde_json::to_string(&Fixed::<2>(f64::NAN)).unwrap(),
            "null"
        );
    }
}

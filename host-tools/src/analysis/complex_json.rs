//! The JSON form of a complex value: `{"re": .., "im": ..}`, as the project's files have had it
//! from the start (num-complex's own serde form is a `[re, im]` pair, and its feature is off).
//! For a field: `#[serde(with = "crate::analysis::complex_json")]` on a `Complex64`,
//! `#[serde(with = "crate::analysis::complex_json::vec")]` on a `Vec<Complex64>`.

use num_complex::Complex64;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

#[derive(Serialize, Deserialize)]
struct ReIm {
    re: f64,
    im: f64,
}

impl From<Complex64> for ReIm {
    fn from(z: Complex64) -> Self {
        Self { re: z.re, im: z.im }
    }
}

impl From<ReIm> for Complex64 {
    fn from(z: ReIm) -> Self {
        Self::new(z.re, z.im)
    }
}

pub fn serialize<S: Serializer>(z: &Complex64, serializer: S) -> Result<S::Ok, S::Error> {
    ReIm::from(*z).serialize(serializer)
}

pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Complex64, D::Error> {
    ReIm::deserialize(deserializer).map(Complex64::from)
}

/// A list of complex values, each `{"re": .., "im": ..}`.
pub mod vec {
    use super::ReIm;
    use num_complex::Complex64;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &[Complex64], serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(v.iter().map(|&z| ReIm::from(z)))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Vec<Complex64>, D::Error> {
        Ok(Vec::<ReIm>::deserialize(deserializer)?.into_iter().map(Complex64::from).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize, Deserialize, Debug, PartialEq)]
    struct One {
        #[serde(with = "super")]
        h: Complex64,
    }

    #[derive(Serialize, Deserialize, Debug, PartialEq)]
    struct Many {
        #[serde(with = "super::vec")]
        response: Vec<Complex64>,
    }

    #[test]
    fn the_re_im_form_written_by_earlier_versions_loads_and_is_written_back_unchanged() {
        let old = r#"{"h":{"re":-2.5e-7,"im":0.1}}"#;
        let one: One = serde_json::from_str(old).unwrap();
        assert_eq!(one.h, Complex64::new(-2.5e-7, 0.1));
        assert_eq!(serde_json::to_string(&one).unwrap(), old);

        let old = r#"{"response":[{"re":1.0,"im":-0.0},{"re":3.5e+300,"im":5e-324}]}"#;
        let many: Many = serde_json::from_str(old).unwrap();
        assert_eq!(many.response, [Complex64::new(1.0, -0.0), Complex64::new(3.5e300, 5e-324)]);
        assert!(many.response[0].im.is_sign_negative());
        assert_eq!(serde_json::to_string(&many).unwrap(), old);
    }

    /// The value type the project had before num-complex, with its derived serde form.
    #[derive(Serialize, Deserialize)]
    struct EarlierComplex {
        re: f64,
        im: f64,
    }

    #[test]
    fn text_and_bits_are_those_of_the_earlier_type() {
        let parts = [0.0, -0.0, 1.0, -1.2345678901234567e-7, std::f64::consts::PI, 1e308, -5e-324, 2.0f64.powi(-1022)];
        for re in parts {
            for im in parts {
                let text = serde_json::to_string(&EarlierComplex { re, im }).unwrap();
                assert_eq!(
                    serde_json::to_string(&One { h: Complex64::new(re, im) }).unwrap(),
                    format!(r#"{{"h":{text}}}"#)
                );
                // serde_json's default parser is not always correctly rounded: compare with
                // what the earlier type read, bit for bit.
                let earlier: EarlierComplex = serde_json::from_str(&text).unwrap();
                let now = serde_json::from_str::<One>(&format!(r#"{{"h":{text}}}"#)).unwrap().h;
                assert_eq!(
                    (now.re.to_bits(), now.im.to_bits()),
                    (earlier.re.to_bits(), earlier.im.to_bits()),
                    "{text}"
                );
            }
        }
    }

    #[test]
    fn half_a_value_is_refused_and_a_pair_is_read_as_re_im() {
        assert!(serde_json::from_str::<One>(r#"{"h":{"re":1.0}}"#)
            .unwrap_err()
            .to_string()
            .contains("missing field `im`"));
        assert!(serde_json::from_str::<Many>(r#"{"response":[{"re":1.0,"im":"x"}]}"#).is_err());
        // serde's derived struct also reads a sequence: num-complex's own `[re, im]` loads too.
        assert_eq!(serde_json::from_str::<One>(r#"{"h":[1.0,2.0]}"#).unwrap().h, Complex64::new(1.0, 2.0));
    }
}

//! Exact sums of `f64` values, for property tests of directed rounding.
//!
//! Every finite `f64` is an integer multiple of 2⁻¹⁰⁷⁴, so it is an
//! integer in fixed point scaled by 2¹⁰⁷⁴: at most 2¹⁰²⁴·2¹⁰⁷⁴ = 2²⁰⁹⁸.
//! [`Fixed`] holds such integers in two's complement over 2 560 bits, room
//! for sums of millions of values near `f64::MAX`, for products with
//! powers of two up to 2⁴⁰⁰, and for values below 2⁴⁴ times powers of two
//! up to 2¹⁴⁰⁰ (`of_scaled` checks that the value fits). Addition is exact, so a test can compare a
//! computed bound with the exact sum of the exact values it bounds.

/// Limbs of 64 bits: 2 560 bits in all.
const LIMBS: usize = 40;

/// An exact multiple of 2⁻¹⁰⁷⁴, in two's complement.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Fixed([u64; LIMBS]);

impl Fixed {
    /// Zero.
    pub const ZERO: Fixed = Fixed([0; LIMBS]);

    /// The exact value of a finite `x` times 2^`k` (`0 ≤ k ≤ 1400`).
    pub fn of_scaled(x: f64, k: u32) -> Fixed {
        assert!(x.is_finite(), "only finite values are exact numbers");
        assert!(k <= 1400);
        let bits = x.to_bits();
        let exp = ((bits >> 52) & 0x7ff) as u32;
        let frac = bits & ((1u64 << 52) - 1);
        // x = m · 2^(shift − 1074)
        let (m, shift) = if exp == 0 {
            (frac, 0)
        } else {
            (frac | (1u64 << 52), exp - 1)
        };
        let shift = shift + k;
        // the top bit of the mantissa, and one more for the sign and for sums
        assert!(
            (shift + 53) as usize + 48 < LIMBS * 64,
            "{x:e}·2^{k} does not fit"
        );
        let mut out = [0u64; LIMBS];
        let (limb, bit) = ((shift / 64) as usize, shift % 64);
        out[limb] |= m << bit;
        if bit > 0 && limb + 1 < LIMBS {
            out[limb + 1] |= m >> (64 - bit);
        }
        let f = Fixed(out);
        if x.is_sign_negative() {
            f.neg()
        } else {
            f
        }
    }

    /// The exact value of a finite `x`.
    pub fn of(x: f64) -> Fixed {
        Fixed::of_scaled(x, 0)
    }

    /// `self + other`, exactly.
    pub fn add(self, other: Fixed) -> Fixed {
        let mut out = [0u64; LIMBS];
        let mut carry = false;
        for ((o, a), b) in out.iter_mut().zip(&self.0).zip(&other.0) {
            let (s, c1) = a.overflowing_add(*b);
            let (s, c2) = s.overflowing_add(u64::from(carry));
            *o = s;
            carry = c1 || c2;
        }
        Fixed(out)
    }

    /// `−self`, exactly.
    pub fn neg(self) -> Fixed {
        let inv = self.0.map(|l| !l);
        let mut one = [0u64; LIMBS];
        one[0] = 1;
        Fixed(inv).add(Fixed(one))
    }

    /// Whether `self < 0`.
    pub fn is_negative(self) -> bool {
        self.0[LIMBS - 1] >> 63 == 1
    }

    /// Whether `self ≤ other`.
    pub fn le(self, other: Fixed) -> bool {
        !other.add(self.neg()).is_negative()
    }

    /// The exact sum of finite values.
    pub fn sum(values: impl IntoIterator<Item = f64>) -> Fixed {
        values
            .into_iter()
            .fold(Fixed::ZERO, |acc, v| acc.add(Fixed::of(v)))
    }
}

/// Whether `bound` is a sound upper bound of the exact value `exact`:
/// `+∞`, or finite and at least `exact` (never `−∞` nor NaN).
pub fn is_upper(bound: f64, exact: Fixed) -> bool {
    bound == f64::INFINITY || (bound.is_finite() && exact.le(Fixed::of(bound)))
}

/// Whether `bound` is a sound lower bound of `exact` (see [`is_upper`]).
pub fn is_lower(bound: f64, exact: Fixed) -> bool {
    bound == f64::NEG_INFINITY || (bound.is_finite() && Fixed::of(bound).le(exact))
}

/// Random values for directed-rounding tests: magnitudes near `f64::MAX`,
/// large, ordinary, subnormal, zeros of both signs, both signs, from a
/// SplitMix64 stream.
pub struct Extreme(u64);

impl Extreme {
    /// A stream from `seed`.
    pub fn new(seed: u64) -> Extreme {
        Extreme(seed)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A uniform number in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// An index below `n`.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// One finite value of a random kind and sign.
    pub fn value(&mut self) -> f64 {
        let sign = if self.next_u64() & 1 == 0 { 1.0 } else { -1.0 };
        let u = self.unit();
        let v = match self.below(8) {
            0 => f64::MAX * (1.0 - u * 1e-3),
            1 => f64::MAX * (0.25 + 0.75 * u),
            2 => 1e300 * (1.0 + u),
            3 => u * 10.0,
            4 => f64::from_bits(1 + self.next_u64() % (1u64 << 52)), // subnormal
            5 => f64::MIN_POSITIVE * (1.0 + u),
            6 => 0.0,
            _ => f64::from_bits(self.next_u64() & 0x7fef_ffff_ffff_ffff), // any finite
        };
        sign * v
    }
}

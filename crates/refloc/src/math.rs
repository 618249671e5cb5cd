//! Small deterministic float helpers (pure arithmetic, identical on every
//! target, so the compiler and a robot compute bit-identical histograms).

/// `e^x` by pure arithmetic: `2^k e^y` with `k` the nearest integer to
/// `x log2(e)`, `y = x - k ln 2` (`|y| <= 0.347`) and a degree-6 Taylor
/// polynomial for `e^y`. Relative error below 5e-7 for `|x| <= 80`; `x` is
/// clamped to that range (NaN gives NaN). Inlined and branch-light, for
/// the SSM affinity's logistic (eq. 4), which runs for every pair of
/// correspondences that passes the rho test (`libm::expf` there was 5% of
/// a real query's cycles: docs/performance.md).
#[inline]
pub fn exp(x: f32) -> f32 {
    if x.is_nan() {
        return x;
    }
    let x = x.clamp(-80.0, 80.0);
    let t = x * core::f32::consts::LOG2_E;
    let k = if t >= 0.0 {
        (t + 0.5) as i32
    } else {
        (t - 0.5) as i32
    };
    // x - k ln 2 with ln 2 split in two (Cody and Waite): `k * LN2_HI` is
    // exact, so the difference keeps the bits a single product would lose.
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    let y = (x - k as f32 * LN2_HI) - k as f32 * LN2_LO;
    let p = 1.0
        + y * (1.0
            + y * (0.5
                + y * (1.0 / 6.0 + y * (1.0 / 24.0 + y * (1.0 / 120.0 + y * (1.0 / 720.0))))));
    // 2^k for k in [-116, 116]: a normal f32 built from its exponent bits.
    p * f32::from_bits(((k + 127) as u32) << 23)
}

/// atan2 approximation, |error| < 1e-5 rad, result in [-pi, pi].
#[inline]
#[allow(clippy::excessive_precision)] // minimax coefficients, kept as derived
pub fn atan2(y: f32, x: f32) -> f32 {
    use core::f32::consts::{FRAC_PI_2, PI};
    let ax = libm::fabsf(x);
    let ay = libm::fabsf(y);
    let mx = if ax > ay { ax } else { ay };
    if !(mx > 0.0) {
        return 0.0;
    }
    let mn = if ax > ay { ay } else { ax };
    let a = mn / mx;
    let s = a * a;
    // Minimax polynomial for atan on [0, 1].
    let mut r = ((-0.013_480_470 * s + 0.057_477_314) * s - 0.121_239_071) * s;
    r = ((r + 0.195_635_925) * s - 0.332_994_597) * s;
    r = (r + 0.999_995_630) * a;
    if ay > ax {
        r = FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = PI - r;
    }
    if y < 0.0 {
        -r
    } else {
        r
    }
}

/// Euclidean norm of a 2-vector.
#[inline]
pub fn norm(v: [f32; 2]) -> f32 {
    libm::sqrtf(v[0] * v[0] + v[1] * v[1])
}

/// Squared distance.
#[inline]
pub fn dist2(a: [f32; 2], b: [f32; 2]) -> f32 {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    dx * dx + dy * dy
}

/// Signed angle (radians, (-pi, pi]) from unit vector `u` to vector `d`.
#[inline]
pub fn signed_angle(u: [f32; 2], d: [f32; 2]) -> f32 {
    atan2(u[0] * d[1] - u[1] * d[0], u[0] * d[0] + u[1] * d[1])
}

#[cfg(test)]
mod tests {
    #[test]
    fn exp_is_close_to_libm() {
        let mut worst = 0.0f32;
        for i in -160_000..=160_000 {
            let x = i as f32 * 5e-4;
            let (got, want) = (super::exp(x), libm::expf(x));
            worst = worst.max(((got - want) / want).abs());
        }
        assert!(worst < 5e-7, "{worst}");
        assert_eq!(super::exp(0.0), 1.0);
        // Clamped beyond +-80, finite and positive; NaN stays NaN.
        assert_eq!(super::exp(1e9), super::exp(80.0));
        assert!(super::exp(-1e9) > 0.0 && super::exp(-1e9) == super::exp(-80.0));
        assert!(super::exp(f32::INFINITY).is_finite());
        assert!(super::exp(f32::NAN).is_nan());
    }

    #[test]
    fn atan2_is_close() {
        let mut worst = 0.0f32;
        for i in 0..2000 {
            let a = -core::f32::consts::PI + i as f32 * 0.00314;
            for r in [0.01f32, 1.0, 100.0] {
                let (y, x) = (r * libm::sinf(a), r * libm::cosf(a));
                let e = (super::atan2(y, x) - libm::atan2f(y, x)).abs();
                worst = worst.max(e.min((e - 2.0 * core::f32::consts::PI).abs()));
            }
        }
        assert!(worst < 2e-5, "worst {worst}");
        assert_eq!(super::atan2(0.0, 0.0), 0.0);
    }
}

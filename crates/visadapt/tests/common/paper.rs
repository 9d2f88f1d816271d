//! The paper's threshold-versus-intensity functions written out again, independently of
//! the library, for the tests of both crates (the command-line tests include this file by
//! path).

/// Eq. 4 (Ferwerda et al. 1996): the photopic threshold `t_p(L_a)` in cd/m², after Fig. 4.
pub fn tp(l: f64) -> f64 {
    let x = l.log10();
    10f64.powf(if x <= -2.6 {
        -0.72
    } else if x >= 1.9 {
        x - 1.255
    } else {
        (0.249 * x + 0.65).powf(2.7) - 0.72
    })
}

/// Eq. 5 (Ferwerda et al. 1996): the scotopic threshold `t_s(L_a)` in scotopic cd/m².
pub fn ts(l: f64) -> f64 {
    let x = l.log10();
    10f64.powf(if x <= -3.94 {
        -2.86
    } else if x >= -1.44 {
        x - 0.395
    } else {
        (0.405 * x + 1.6).powf(2.18) - 2.86
    })
}

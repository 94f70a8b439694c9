//! tune-ff's decision on a fitted curve (a pure function).

/// tune-ff's decision: a flat curve (an RMS error that hardly depends on the gain, with a
/// few % of scatter) gives an optimum too uncertain to choose, and says so; a clear one is
/// chosen; a fitted vertex outside the window or no minimum is not.
#[test]
fn tune_ff_says_when_the_curve_is_too_flat_to_choose() {
    use gms_bench::decide;
    use gms_ident::optimum::fit_minimum;
    let scatter = [0.03, -0.02, 0.01, -0.03, 0.02, -0.01, 0.0, 0.025, -0.015];
    let gains: Vec<f64> = (0..18).map(|i| 0.6 + 0.05 * (i % 9) as f64).collect();
    let window = (0.6, 1.0);
    // Flat: 1.3 counts within ±3 %, a curvature far below the scatter.
    let flat: Vec<(f64, f64)> = gains
        .iter()
        .enumerate()
        .map(|(i, &g)| (g, 1.3 * (1.0 + 0.02 * (g - 0.8).powi(2) + scatter[i % 9])))
        .collect();
    let (decided, note) = decide(fit_minimum(&flat), window);
    assert!(!decided, "{:?}", fit_minimum(&flat));
    let note = note.unwrap();
    assert!(
        note.contains("too flat") || note.contains("no minimum") || note.contains("outside"),
        "{note}"
    );
    // Clear: the default plant's curvature (RMS² rises 28 per unit² from 1.7).
    let clear: Vec<(f64, f64)> = gains
        .iter()
        .enumerate()
        .map(|(i, &g)| {
            (
                g,
                (1.7 + 28.0 * (g - 0.8f64).powi(2)).sqrt() * (1.0 + scatter[i % 9]),
            )
        })
        .collect();
    let o = fit_minimum(&clear).unwrap();
    assert_eq!(decide(Some(o), window), (true, None));
    assert!((o.at - 0.8).abs() < 2.0 * o.se + 0.01, "{o:?}");
    // Outside the window, or nothing: not chosen.
    assert!(!decide(Some(o), (0.9, 1.2)).0);
    assert!(!decide(None, window).0);
}

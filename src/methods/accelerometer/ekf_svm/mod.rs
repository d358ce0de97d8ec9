//! Method 003: accelerometer fault detection and classification from attitude-EKF residuals with a
//! bottom-up SVM decision tree (`docs/findings-seed003.md`; the patent "一种飞机飞行控制系统的加速度计故障
//! 监测方法", steps 4-5, paragraphs 0146-0148). The residual comes from
//! [`crate::methods::accelerometer::attitude::AttitudeEkf`]; the trials from [`crate::methods::accelerometer::imu`].
//!
//! # Pipeline
//! 1. Residuals `e(k) = z(k) - g(q(k|k-1))` and the expected gravity direction `g(q(k|k-1))` of each
//!    sample ([`ResidualSample`]; [`simulate_trial`] runs scenario and filter together).
//! 2. Detection ([`ResidualDetector`]): `T(k) = n |mean of the last n residuals|^2 / sigma_z^2`, with
//!    `sigma_z = sigma_a / g0` the residual noise per component. For white residuals it is chi-square
//!    with about 2 degrees of freedom (normalisation leaves the component along gravity almost
//!    noise-free). The alarm is the first `T >= threshold`; the threshold of [`DetectionParams::seed`]
//!    is set from fault-free trials (see there), and a study calibrates its own from its fault-free
//!    trials (the project's threshold workflow: record `T`'s running maximum, choose afterwards).
//! 3. Features of a window of `n` residual samples ([`features`], [`FEATURE_NAMES`]).
//! 4. Classification into normal / bias / gain / stuck ([`FaultClass`]) by the seed's SVM decision tree
//!    ([`SvmTree`]) or, for comparison, a flat one-against-one SVM ([`OneVsOne`]), both in a
//!    [`Classifier`] that also holds the feature standardisation and settings, saved as JSON.
//!
//! # Features (per accelerometer axis j = x, y, z; 12 in all, dimensionless)
//! With `e_j(i)` the residual and `g_j(i)` the expected gravity direction at the window's samples,
//! `t_i = i dt`:
//! - `mean_j`: the mean of `e_j`. Any fault shifts it (residual expectation of the seed: zero when
//!   healthy, non-zero under a fault). A bias shifts it by `alpha / |a| (1 - z_j^2)` at once.
//! - `slope_j`: least-squares slope of `e_j` against `t` (1/s). A bias's shift is largest at the onset
//!   and decays as the filter absorbs it into the attitude (slope against the mean); a stuck output's
//!   grows from zero as the attitude moves away from where it froze (slope with the mean); a gain's
//!   follows the axis' share of gravity.
//! - `noise_j`: RMS of `e_j` about that line. A stuck output has no noise left (its residual is the
//!   smooth `gamma/|a| - g_j`), a gain scales the noise by `beta`, a bias leaves it.
//! - `sensitivity_j = cov(e_j, g_j) / (var(g_j) + floor^2)`: the regression of the residual on the
//!   gravity share. About -1 for a stuck axis (`e_j ~ const - g_j`), about `(beta - 1)(1 - 3 g_j^2)`
//!   for a gain (`e_j ~ (beta - 1) g_j (1 - g_j^2)`), near 0 for a bias and when healthy. The floor
//!   (0.02 by default: 1.1 deg of gravity swing) keeps it near 0 when the attitude barely moves and
//!   nothing can be told.
//!
//! # Scaling (fitted on the training set, saved with the model: [`Standardizer`])
//! Per feature, `u = asinh((x - m_0) / s_0)` with `m_0`, `s_0` the mean and standard deviation over the
//! normal class, then `(u - mean(u)) / std(u)` over all training examples. Fault sizes span a decade and
//! the features grow with the size, so plain standardisation lets the large faults set the scale and
//! crowds the small ones against the healthy cluster; in units of the healthy spread and compressed
//! logarithmically beyond it, a feature says how abnormal it is and the classifier reads the signature's
//! shape more than its size (measured on 300 trials per class: validation accuracy 0.82 with plain
//! standardisation, 0.93 with this, same SVM settings).
//!
//! # Which window (what a runner passes)
//! The classifier must see windows aligned as in training. [`TrialDesign`] makes training examples
//! from the window of `window_len` samples starting `window_delay_s` after the onset (for a fault-free
//! trial, after its drawn nominal onset, which the fault is not applied at), so a study that evaluates
//! on fresh trials passes the same window: `trace.samples[start..start + window_len]` with
//! `start = ceil((onset_s + window_delay_s) / dt_s)` ([`window_start`]). A runner that classifies after
//! its detector instead (onset unknown) trains and evaluates with the window starting at the alarm.
//!
//! # Separability and the bottom-up tree (patent paragraph 0147)
//! The patent names the inter-class separability `s_ij` but its formula is an image lost from the text;
//! this is the measure of the SVM-decision-tree literature it follows (separability measure
//! `s_ij = d_ij / (sigma_i + sigma_j)`, e.g. Tang, Wang, Chen, "A new binary tree multi-class SVM
//! algorithm", Computer Engineering and Applications 2005), computed in the standardised feature space:
//! ```text
//! c_i = mean of class i,   sigma_i = 1/(n_i - 1) sum_x |x - c_i|   (class spread),
//! d_ij = |c_i - c_j|,      s_ij = d_ij / (sigma_i + sigma_j)
//! ```
//! Training ([`Classifier::train`] with [`Scheme::Tree`]): start with one group per class; compute `s`
//! for every pair of groups (a merged group is one class: its samples pooled); train a binary SVM on the
//! least separable pair (positive: the group listed first); merge the pair; repeat until one group, the
//! root. Classification runs top-down: each internal node's SVM sends the sample to its positive or
//! negative subtree until a leaf. The merges, with every candidate pair's separability, are kept
//! ([`SvmTree::merges`]).
//!
//! # SVMs
//! Binary C-SVMs of `linfa-svm` (SMO solver), linear or Gaussian kernel `exp(-gamma |x - x'|^2)`;
//! [`SvmParams::seed`] gives the defaults and why. A trained `linfa_svm::Svm` is serde-serialisable
//! (its support vectors, weights, offset and kernel), so the whole [`Classifier`] is saved as JSON.
//!
//! The parts, each one job: `features.rs` (the classes, a residual window's features, the errors),
//! `detection.rs` (the detection rule and the trials and examples it is trained and evaluated on),
//! `svm.rs` (binary SVMs, standardisation, separability), `tree.rs` (the decision tree and the
//! one-against-one vote) and `classifier.rs` (a study's classifier, its training and JSON, the confusion
//! matrix).
#![allow(non_snake_case)]

mod classifier;
mod detection;
mod features;
mod svm;
mod tree;

pub use classifier::*;
pub use detection::*;
pub use features::*;
pub use svm::*;
pub use tree::*;

#[cfg(test)]
mod tests {

    use super::ConfusionMatrix;
    use super::tree::ClassRows;
    use super::*;

    use nalgebra::Vector3;

    use crate::methods::accelerometer::imu::ImuScenarioParams;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;
    use std::sync::OnceLock;

    /// `per_class` trials of every class of [`TrialDesign::seed`], classes interleaved, from one RNG.
    fn examples(per_class: usize, seed: u64) -> Vec<Example> {
        let design = TrialDesign::seed();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..per_class)
            .flat_map(|_| FaultClass::ALL)
            .map(|class| design.draw_example(class, &mut rng).unwrap())
            .collect()
    }

    /// Training set (RNG seed 11) and test set (seed 12), 150 trials per class each; neither seed was
    /// used to choose the SVM settings.
    fn data() -> &'static (Vec<Example>, Vec<Example>) {
        static DATA: OnceLock<(Vec<Example>, Vec<Example>)> = OnceLock::new();
        DATA.get_or_init(|| (examples(150, 11), examples(150, 12)))
    }

    fn trained(scheme: Scheme) -> Classifier {
        Classifier::train(scheme, &data().0, FeatureParams::seed(), SvmParams::seed()).unwrap()
    }

    #[test]
    fn features_follow_their_definitions() {
        let params = FeatureParams { dt_s: 0.1, window_len: 50, sensitivity_floor: 0.0, relative_noise: false };
        // x: a line 0.01 + 0.2 t; y: -0.5 times the gravity share plus 0.3; z: alternating +-0.01.
        let window: Vec<ResidualSample> = (0..50)
            .map(|i| {
                let t = i as f64 * 0.1;
                let g = [0.0, (0.7 * t).sin() * 0.4, -0.9];
                let e = [0.01 + 0.2 * t, 0.3 - 0.5 * g[1], if i % 2 == 0 { 0.01 } else { -0.01 }];
                ResidualSample { residual: e, predicted: g }
            })
            .collect();
        let f = features(&window, &params).unwrap();
        let t_mean = 0.1 * 49.0 / 2.0;
        assert!((f[0] - (0.01 + 0.2 * t_mean)).abs() < 1e-12);
        assert!((f[1] - 0.2).abs() < 1e-12 && f[2] < 1e-12, "a line: slope 0.2, no noise");
        assert_eq!(f[3], 0.0, "no swing of the gravity share: sensitivity 0");
        assert!((f[7] + 0.5).abs() < 1e-12, "sensitivity is the regression on the gravity share");
        assert!(f[8].abs() < 1e-12 && (f[10] - 0.01).abs() < 1e-4);
        // The floor pulls the sensitivity towards 0 when the swing is small against it.
        let floored = features(&window, &FeatureParams { sensitivity_floor: 1.0, ..params }).unwrap();
        assert!(floored[7] > -0.1 && floored[7] < 0.0);
        assert_eq!(features(&window[..49], &params), Err(ClassifierError::WindowLength { expected: 50, got: 49 }));
        let mut bad = window.clone();
        bad[7].residual[1] = f64::NAN;
        assert_eq!(features(&bad, &params), Err(ClassifierError::NonFiniteSample { index: 7 }));
        // Relative noise: z's 0.01 over the same alternation of 0.04 before the window is 0.25; x's
        // reference is a line (no noise), which leaves x's value; without the option nothing changes.
        let reference: Vec<ResidualSample> = (0..20)
            .map(|i| ResidualSample {
                residual: [0.1 * i as f64, 0.0, if i % 2 == 0 { 0.04 } else { -0.04 }],
                predicted: [0.0; 3],
            })
            .collect();
        let relative = FeatureParams { relative_noise: true, ..params };
        let r = features_with_reference(&window, &reference, &relative).unwrap();
        assert!((r[10] - 0.25).abs() < 0.01, "{}", r[10]);
        assert_eq!((r[2], r[0], r[1]), (f[2], f[0], f[1]));
        assert_eq!(features_with_reference(&window, &reference, &params).unwrap(), f);
        assert!(features_with_reference(&window, &reference[..2], &relative).is_err());
        assert_eq!(window_start(8.0, 0.0, 0.01), 800);
        assert_eq!(window_start(8.001, 0.5, 0.01), 851);
    }

    /// `s = d / (sigma_a + sigma_b)` on hand-computed sets: centres (0, 0) and (3, 4) (d = 5), spreads
    /// (1 + 1) / 1 = 2 and (2 + 2 + 2) / 2 = 3, so s = 1.
    #[test]
    fn separability_matches_its_formula() {
        let a: Vec<&[f64]> = vec![&[1.0, 0.0], &[-1.0, 0.0]];
        let b: Vec<&[f64]> = vec![&[5.0, 4.0], &[1.0, 4.0], &[3.0, 4.0]];
        // b's centre is (3, 4); distances 2, 2, 0 -> spread 4 / 2 = 2.
        assert!((separability(&a, &b) - 5.0 / (2.0 + 2.0)).abs() < 1e-15);
        assert_eq!(separability(&a, &a), 0.0);
        let point: Vec<&[f64]> = vec![&[7.0, 0.0], &[7.0, 0.0]];
        let other: Vec<&[f64]> = vec![&[0.0, 0.0], &[0.0, 0.0]];
        assert_eq!(separability(&point, &other), f64::INFINITY);
    }

    /// The separability formula written out again, on owned rows.
    fn separability_written_out(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
        let stats = |rows: &[Vec<f64>]| {
            let n = rows.len() as f64;
            let c: Vec<f64> = (0..rows[0].len()).map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n).collect();
            let dist = |r: &Vec<f64>| r.iter().zip(&c).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
            let spread = rows.iter().map(dist).sum::<f64>() / (n - 1.0);
            (c, spread)
        };
        let ((ca, sa), (cb, sb)) = (stats(a), stats(b));
        ca.iter().zip(&cb).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt() / (sa + sb)
    }

    /// Independent re-computation of a separability the tree should have used: the scaled rows of the
    /// examples of two groups of classes.
    fn recomputed(classifier: &Classifier, examples: &[Example], first: &[FaultClass], second: &[FaultClass]) -> f64 {
        let rows = |set: &[FaultClass]| -> Vec<Vec<f64>> {
            examples
                .iter()
                .filter(|e| set.contains(&e.class))
                .map(|e| classifier.standardizer.apply(&e.features))
                .collect()
        };
        separability_written_out(&rows(first), &rows(second))
    }

    /// Checks that `tree` is a full binary tree over the four classes (3 splits, 4 leaves, each class
    /// once) and that each merge took the least separable of the candidate pairs, with separabilities
    /// that agree with an independent computation to 1e-9.
    fn check_tree(classifier: &Classifier, examples: &[Example]) {
        let tree = classifier.tree().unwrap();
        fn count(node: &TreeNode) -> (usize, usize) {
            match node {
                TreeNode::Leaf { .. } => (0, 1),
                TreeNode::Split { positive, negative, .. } => {
                    let (a, b) = (count(positive), count(negative));
                    (a.0 + b.0 + 1, a.1 + b.1)
                }
            }
        }
        assert_eq!(count(&tree.root), (3, 4));
        assert_eq!(tree.root.classes(), FaultClass::ALL.to_vec());
        assert_eq!(tree.merges.len(), 3);
        assert_eq!(tree.merges.iter().map(|m| m.candidates.len()).collect::<Vec<_>>(), [6, 3, 1]);
        for merge in &tree.merges {
            for c in &merge.candidates {
                let s = recomputed(classifier, examples, &c.first, &c.second);
                assert!((s - c.separability).abs() < 1e-9 * s.max(1.0), "{c:?} vs {s}");
            }
            let least = merge.candidates.iter().map(|c| c.separability).fold(f64::INFINITY, f64::min);
            assert_eq!(merge.separability, least);
            let chosen = merge.candidates.iter().find(|c| c.separability == least).unwrap();
            assert_eq!((&chosen.first, &chosen.second), (&merge.positive, &merge.negative));
        }
        // The root splits what the last merge joined.
        let last = tree.merges.last().unwrap();
        let TreeNode::Split { positive, negative, .. } = &tree.root else { panic!("root is a leaf") };
        assert_eq!((positive.classes(), negative.classes()), (sorted(&last.positive), sorted(&last.negative)));
    }

    fn sorted(c: &[FaultClass]) -> Vec<FaultClass> {
        let mut c = c.to_vec();
        c.sort();
        c
    }

    /// The tree-building step on four synthetic clusters (already standardised rows) whose
    /// separabilities are known in advance: unit spread in 12 dimensions (a mean distance from the centre
    /// near sqrt(12)), centres on the first axis at bias 0, gain 3, stuck 8, normal 20. The tree must
    /// join bias and gain first, then stuck, and put normal alone under the root; each merge's
    /// separabilities match an independent computation and it takes the least separable pair; the cluster
    /// centres are classified top-down to their own class.
    #[test]
    fn tree_merges_follow_the_separabilities_on_synthetic_clusters() {
        use FaultClass::*;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let centre = |c: FaultClass| match c {
            Normal => 20.0,
            Bias => 0.0,
            Gain => 3.0,
            Stuck => 8.0,
        };
        let owned: Vec<(FaultClass, Vec<Vec<f64>>)> = FaultClass::ALL
            .into_iter()
            .map(|class| {
                let rows = (0..60)
                    .map(|_| {
                        (0..FEATURE_COUNT)
                            .map(|j| {
                                let n: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                                if j == 0 { centre(class) + n } else { n }
                            })
                            .collect()
                    })
                    .collect();
                (class, rows)
            })
            .collect();
        let rows: ClassRows = owned.iter().map(|(c, r)| (*c, r.iter().map(|x| &x[..]).collect())).collect();
        let tree = SvmTree::train(&rows, &SvmParams::seed(), true).unwrap();
        let merges = &tree.merges;
        assert_eq!((sorted(&merges[0].positive), sorted(&merges[0].negative)), (vec![Bias], vec![Gain]));
        assert_eq!((sorted(&merges[1].positive), sorted(&merges[1].negative)), (vec![Bias, Gain], vec![Stuck]));
        assert_eq!((sorted(&merges[2].positive), sorted(&merges[2].negative)), (vec![Normal], vec![Bias, Gain, Stuck]));
        for merge in merges {
            for c in &merge.candidates {
                let pick = |set: &[FaultClass]| -> Vec<Vec<f64>> {
                    owned.iter().filter(|(k, _)| set.contains(k)).flat_map(|(_, r)| r.clone()).collect()
                };
                let s = separability_written_out(&pick(&c.first), &pick(&c.second));
                assert!((s - c.separability).abs() < 1e-12, "{c:?} vs {s}");
            }
            let least = merge.candidates.iter().map(|c| c.separability).fold(f64::INFINITY, f64::min);
            assert_eq!(merge.separability, least);
        }
        // Top-down classification of the cluster centres.
        let classifies_the_centres = |tree: &SvmTree| {
            for class in FaultClass::ALL {
                let mut x = vec![0.0; FEATURE_COUNT];
                x[0] = centre(class);
                assert_eq!(tree.classify(&x), class);
            }
        };
        classifies_the_centres(&tree);
        // The opposite order merges the farthest pair first (normal at 20 with bias at 0), each merge the
        // most separable candidate; it still classifies the centres.
        let reversed = SvmTree::train(&rows, &SvmParams::seed(), false).unwrap();
        let first = &reversed.merges[0];
        assert_eq!((sorted(&first.positive), sorted(&first.negative)), (vec![Normal], vec![Bias]));
        for merge in &reversed.merges {
            let most = merge.candidates.iter().map(|c| c.separability).fold(f64::NEG_INFINITY, f64::max);
            assert_eq!(merge.separability, most);
        }
        classifies_the_centres(&reversed);
    }

    /// Balanced weights at a node of one class against three: on overlapping clusters (centres 0 and 1.5,
    /// unit spread) with 40 examples against 360, equal `C` gives the boundary to the large side and the
    /// small class's examples are voted away; weighted by the inverse of each side's size they are kept.
    /// Measured: 2 of the 40 on their own side with equal `C`, 35 balanced.
    #[test]
    fn balanced_weights_keep_the_small_side_of_a_merged_node() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let mut draw = |centre: f64, n: usize| -> Vec<Vec<f64>> {
            (0..n)
                .map(|_| {
                    (0..2)
                        .map(|j| {
                            let e: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                            if j == 0 { centre + e } else { e }
                        })
                        .collect()
                })
                .collect()
        };
        let (small, large) = (draw(0.0, 40), draw(1.5, 360));
        let (small, large): (Vec<&[f64]>, Vec<&[f64]>) =
            (small.iter().map(|x| &x[..]).collect(), large.iter().map(|x| &x[..]).collect());
        let recall = |balanced: bool| {
            let params = SvmParams { balanced, ..SvmParams::seed() };
            let svm = BinarySvm::train(&small, &large, &params, "test".into()).unwrap();
            small.iter().filter(|x| svm.decision(x) >= 0.0).count()
        };
        let (equal, balanced) = (recall(false), recall(true));
        assert!(equal < 10 && balanced > 30, "small-side examples kept: equal C {equal}, balanced {balanced} of 40");
    }

    /// On residual features (150 trials per class, RNG seed 11) the tree merges the least separable
    /// pair first and follows the separabilities up to the root. Measured: normal/bias 0.071 is the least
    /// separable pair (a small bias on an axis near vertical hardly moves the gravity direction; the
    /// other pairs 0.20-0.61), then {normal, bias} + gain at 0.249, a near tie with gain/stuck at 0.250
    /// (with the validation seed the latter won: the shape past the first merge is fragile on these
    /// classes), and the root splits {normal, bias, gain} from stuck at 0.392.
    #[test]
    fn tree_on_residual_features_follows_the_separabilities() {
        let classifier = trained(Scheme::Tree);
        check_tree(&classifier, &data().0);
        for m in &classifier.tree().unwrap().merges {
            eprintln!(
                "merged {:?} with {:?} at s = {:.3}; candidates {:?}",
                m.positive, m.negative, m.separability, m.candidates
            );
        }
        let first = &classifier.tree().unwrap().merges[0];
        assert_eq!(
            sorted(&[first.positive.clone(), first.negative.clone()].concat()),
            [FaultClass::Normal, FaultClass::Bias]
        );
    }

    /// Train on one RNG seed, test on fresh trials of another (150 per class each). Floors: accuracy
    /// 0.85 for both, recall normal 0.95, bias 0.80, gain 0.60, stuck 0.85. Measured: tree accuracy
    /// 0.898 (recall 0.993, 0.920, 0.733, 0.947), flat one-against-one 0.902 (0.993, 0.920, 0.740,
    /// 0.953). Most errors are small gains taken for biases (32 of 150: within a second the gravity
    /// share of the axis barely changes, so a gain looks like a constant shift).
    #[test]
    fn tree_and_flat_classify_fresh_trials_above_the_floor() {
        for scheme in [Scheme::Tree, Scheme::OneVsOne] {
            let classifier = trained(scheme);
            let (matrix, failed) = ConfusionMatrix::of(&classifier, &data().1);
            assert_eq!(failed, 0);
            let recall = matrix.recall();
            eprintln!("{scheme:?}: accuracy {:.3}, recall {recall:?}, {:?}", matrix.accuracy(), matrix.counts);
            assert!(matrix.accuracy() > 0.85, "{scheme:?}: {matrix:?}");
            for (class, floor) in FaultClass::ALL.into_iter().zip([0.95, 0.80, 0.60, 0.85]) {
                assert!(recall[class.index()] > floor, "{scheme:?} {class:?}: {recall:?}");
            }
        }
    }

    /// JSON round trip (string and file) gives a classifier that classifies every test example as
    /// before, with decision values equal to 1e-12 (serde_json's float parsing may differ from the
    /// written value in the last bit).
    #[test]
    fn saved_and_loaded_classifiers_classify_identically() {
        let dir = tempfile::tempdir().unwrap();
        for scheme in [Scheme::Tree, Scheme::OneVsOne] {
            let classifier = trained(scheme);
            let path = dir.path().join(format!("{scheme:?}.json"));
            classifier.save(&path).unwrap();
            let loaded = Classifier::load(&path).unwrap();
            let from_string = Classifier::from_json(&classifier.to_json().unwrap()).unwrap();
            for other in [&loaded, &from_string] {
                assert_eq!(other.features, classifier.features);
                for e in &data().1 {
                    assert_eq!(other.classify(&e.features), classifier.classify(&e.features));
                }
                let x = classifier.standardizer.apply(&data().1[0].features);
                let decisions = |c: &Classifier| -> Vec<f64> {
                    match &c.model {
                        ClassifierModel::Tree(t) => {
                            t.merges.iter().map(|_| 0.0).chain(node_decisions(&t.root, &x)).collect()
                        }
                        ClassifierModel::OneVsOne(f) => f.machines.iter().map(|m| m.2.decision(&x)).collect(),
                    }
                };
                for (a, b) in decisions(&classifier).iter().zip(decisions(other)) {
                    assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{a} vs {b}");
                }
            }
        }
        let missing = dir.path().join("missing.json");
        assert!(matches!(Classifier::load(&missing), Err(ClassifierError::Io { .. })));
        let wrong = trained(Scheme::Tree).to_json().unwrap().replace(CLASSIFIER_FORMAT, "other/9");
        assert!(matches!(Classifier::from_json(&wrong), Err(ClassifierError::Format { .. })));
        assert!(matches!(Classifier::from_json("{"), Err(ClassifierError::Json(_))));
    }

    fn node_decisions(node: &TreeNode, x: &[f64]) -> Vec<f64> {
        match node {
            TreeNode::Leaf { .. } => Vec::new(),
            TreeNode::Split { svm, positive, negative, .. } => {
                let mut d = vec![svm.decision(x)];
                d.extend(node_decisions(positive, x));
                d.extend(node_decisions(negative, x));
                d
            }
        }
    }

    /// The default threshold (60) raises no alarm after 3 s in 200 fresh fault-free trials (RNG seed 21;
    /// measured largest `T` 49.5) nor before the onset of faulty ones, and detects within 2 s of the
    /// onset at least 95 of 100 biases and every gain and stuck fault (100 trials per kind, seed 22).
    /// Measured: biases 98 (median delay 0.03 s, 90th percentile 0.16 s; the two missed are small and
    /// on an axis near vertical), gains 100 (0.01 s, 0.04 s), stuck 100 (0.12 s, 0.59 s).
    #[test]
    fn detection_threshold_bounds_fault_free_trials() {
        let design = TrialDesign::seed();
        let params = DetectionParams::seed();
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let mut largest = 0.0f64;
        for _ in 0..200 {
            let (scenario, _) = design.draw_trial(FaultClass::Normal, &mut rng);
            let trace = simulate_trial(scenario, &design.ekf, &mut rng).unwrap();
            let statistics = detection_statistics(&trace.samples, &params);
            largest = largest.max(statistics[300..].iter().cloned().fold(0.0, f64::max));
        }
        assert!(largest < params.threshold, "largest fault-free statistic {largest}");
        let mut rng = ChaCha8Rng::seed_from_u64(22);
        for class in [FaultClass::Bias, FaultClass::Gain, FaultClass::Stuck] {
            let mut delays = Vec::new();
            for _ in 0..100 {
                let (scenario, onset_s) = design.draw_trial(class, &mut rng);
                let trace = simulate_trial(scenario, &design.ekf, &mut rng).unwrap();
                let statistics = detection_statistics(&trace.samples, &params);
                let k0 = window_start(onset_s, 0.0, trace.dt_s);
                assert_eq!(
                    first_alarm(&statistics, params.threshold, 300),
                    first_alarm(&statistics, params.threshold, k0)
                );
                let alarm = first_alarm(&statistics, params.threshold, k0);
                delays.push(alarm.map_or(f64::INFINITY, |k| (k - k0) as f64 * trace.dt_s));
            }
            delays.sort_by(f64::total_cmp);
            let within_2_s = delays.iter().filter(|d| **d < 2.0).count();
            eprintln!(
                "{class:?}: {within_2_s} of 100 within 2 s, delay median {} s, 90 % {} s (healthy max T {largest})",
                delays[50], delays[90]
            );
            // A bias on an axis near vertical hardly moves the gravity direction: some go unseen.
            let floor = if class == FaultClass::Bias { 95 } else { 100 };
            assert!(within_2_s >= floor, "{class:?}: {delays:?}");
        }
    }

    /// The detector's statistic is `n |mean|^2 / sigma^2` of the last `n` residuals, none before the
    /// window fills, NaN while a non-finite residual is in it.
    #[test]
    fn detector_statistic_is_the_windowed_mean_norm() {
        let params = DetectionParams { window: 4, residual_std: 0.5, threshold: 3.0 };
        let mut d = ResidualDetector::new(params);
        let r = |x: f64| Vector3::new(x, 0.0, 0.0);
        assert_eq!([d.push(&r(1.0)), d.push(&r(1.0)), d.push(&r(1.0))], [None, None, None]);
        assert_eq!(d.push(&r(1.0)), Some(4.0 * 1.0 / 0.25));
        assert_eq!(d.push(&r(-1.0)), Some(4.0 * 0.25 / 0.25));
        assert!(d.alarms(4.0) && !d.alarms(1.0));
        assert!(d.push(&r(f64::NAN)).unwrap().is_nan());
        assert_eq!(first_alarm(&[f64::NAN, 1.0, 5.0, 2.0, 7.0], 3.0, 0), Some(2));
        assert_eq!(first_alarm(&[f64::NAN, 1.0, 5.0, 2.0, 7.0], 3.0, 3), Some(4));
    }

    #[test]
    fn classifier_misuse_is_an_error_value() {
        let (train, test) = data();
        let classifier = trained(Scheme::OneVsOne);
        assert_eq!(classifier.classify(&[0.0; 3]), Err(ClassifierError::FeatureCount { expected: 12, got: 3 }));
        let mut x = test[0].features;
        x[4] = f64::INFINITY;
        assert_eq!(classifier.classify(&x), Err(ClassifierError::NonFiniteFeature));
        let one_stuck: Vec<Example> = train
            .iter()
            .filter(|e| e.class != FaultClass::Stuck)
            .cloned()
            .chain(train.iter().find(|e| e.class == FaultClass::Stuck).cloned())
            .collect();
        assert_eq!(
            Classifier::train(Scheme::Tree, &one_stuck, FeatureParams::seed(), SvmParams::seed()),
            Err(ClassifierError::TooFewExamples { class: FaultClass::Stuck, count: 1 })
        );
        let bad = SvmParams { c: 0.0, ..SvmParams::seed() };
        assert!(matches!(
            Classifier::train(Scheme::Tree, train, FeatureParams::seed(), bad),
            Err(ClassifierError::Params(_))
        ));
        let mut with_nan = train.clone();
        with_nan[3].features[0] = f64::NAN;
        assert_eq!(
            Classifier::train(Scheme::Tree, &with_nan, FeatureParams::seed(), SvmParams::seed()),
            Err(ClassifierError::NonFiniteExample { index: 3 })
        );
        let design = TrialDesign::seed();
        let short = ImuScenarioParams { duration_s: 5.0, ..ImuScenarioParams::seed() };
        let trace = simulate_trial(short, &design.ekf, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        assert_eq!(
            design.example(&trace, 4.95, FaultClass::Normal),
            Err(ClassifierError::TrialTooShort { end: 595, samples: 500 })
        );
        let coarse = ResidualTrace { dt_s: 0.02, ..trace.clone() };
        assert!(matches!(design.example(&coarse, 1.0, FaultClass::Normal), Err(ClassifierError::SamplePeriod { .. })));
        // Three classes train a two-split tree without the missing one.
        let three: Vec<Example> = train.iter().filter(|e| e.class != FaultClass::Gain).cloned().collect();
        let c = Classifier::train(Scheme::Tree, &three, FeatureParams::seed(), SvmParams::seed()).unwrap();
        assert_eq!(c.tree().unwrap().merges.len(), 2);
        assert!(!c.tree().unwrap().root.classes().contains(&FaultClass::Gain));
    }
}

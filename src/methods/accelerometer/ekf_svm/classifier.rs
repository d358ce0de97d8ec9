//! A trained classifier as a study names it (scheme, window, training data), its training, its
//! persistence as JSON, and the confusion matrix of its predictions.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::detection::*;
use super::features::*;
use super::svm::*;
use super::tree::*;

/// Which multi-class scheme.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ClassifierModel {
    Tree(SvmTree),
    OneVsOne(OneVsOne),
}

/// A trained classifier: feature settings, standardisation and the SVMs; saved and loaded as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Classifier {
    pub format: String,
    pub feature_names: Vec<String>,
    pub features: FeatureParams,
    pub svm: SvmParams,
    pub standardizer: Standardizer,
    pub model: ClassifierModel,
}

/// Which scheme to train.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scheme {
    /// The seed's bottom-up decision tree (least separable pair merged first).
    Tree,
    /// The same tree built in the opposite order, the most separable pair first (comparison).
    TreeMostSeparableFirst,
    /// Flat one-against-one (comparison).
    OneVsOne,
}

/// Which window a classifier is trained on and classifies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClassifierWindow {
    /// The window after the true onset, for every trial detected or not: an oracle.
    Onset,
    /// The window from the residual detector's alarm, as the patent classifies online; no alarm, no
    /// classification (the trial is called normal).
    Alarm,
}

/// What a classifier is trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainingData {
    /// Simulated trials of the deck's scenario (the training seed).
    #[default]
    Simulation,
    /// Faults injected into the replayed log's training part (`log.train_s`), kept apart in time from
    /// the evaluated part.
    Log,
}

impl TrainingData {
    pub fn name(self) -> &'static str {
        match self {
            TrainingData::Simulation => "simulation",
            TrainingData::Log => "log",
        }
    }
}

impl Scheme {
    /// The deck's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Scheme::Tree => "tree",
            Scheme::TreeMostSeparableFirst => "tree_most_separable_first",
            Scheme::OneVsOne => "flat",
        }
    }
}

impl ClassifierWindow {
    pub fn name(self) -> &'static str {
        match self {
            ClassifierWindow::Onset => "onset",
            ClassifierWindow::Alarm => "alarm",
        }
    }
}

/// One classifier of a study: its name (the detector column), scheme, window and class weighting.
#[derive(Debug, Clone, PartialEq)]
pub struct ClassifierSpec {
    pub name: String,
    pub scheme: Scheme,
    pub window: ClassifierWindow,
    pub balanced: bool,
    pub trained_on: TrainingData,
}

impl ClassifierSpec {
    /// The classifiers of a deck without `[[classifier]]`: the tree and the flat SVM on the onset window.
    pub fn defaults() -> Vec<ClassifierSpec> {
        [("tree", Scheme::Tree), ("flat", Scheme::OneVsOne)]
            .map(|(name, scheme)| ClassifierSpec {
                name: name.into(),
                scheme,
                window: ClassifierWindow::Onset,
                balanced: false,
                trained_on: TrainingData::Simulation,
            })
            .into()
    }
}

impl Classifier {
    /// Trains `scheme` on `examples` (every class needs at least 2; classes absent from the examples are
    /// left out of the model), standardising with their mean and standard deviation.
    pub fn train(
        scheme: Scheme,
        examples: &[Example],
        features: FeatureParams,
        svm: SvmParams,
    ) -> Result<Self, ClassifierError> {
        svm.validate()?;
        if let Some(index) = examples.iter().position(|e| !e.features.iter().all(|v| v.is_finite())) {
            return Err(ClassifierError::NonFiniteExample { index });
        }
        let raw: Vec<&[f64]> = examples.iter().map(|e| &e.features[..]).collect();
        if raw.is_empty() {
            return Err(ClassifierError::TooFewExamples { class: FaultClass::Normal, count: 0 });
        }
        let healthy: Vec<&[f64]> =
            examples.iter().filter(|e| e.class == FaultClass::Normal).map(|e| &e.features[..]).collect();
        let standardizer = Standardizer::fit(&raw, &healthy);
        let scaled: Vec<Vec<f64>> = raw.iter().map(|x| standardizer.apply(x)).collect();
        let mut rows: ClassRows = Vec::new();
        for class in FaultClass::ALL {
            let r: Vec<&[f64]> =
                examples.iter().zip(&scaled).filter(|(e, _)| e.class == class).map(|(_, x)| &x[..]).collect();
            match r.len() {
                0 => {}
                1 => return Err(ClassifierError::TooFewExamples { class, count: 1 }),
                _ => rows.push((class, r)),
            }
        }
        if rows.len() < 2 {
            let class = rows.first().map_or(FaultClass::Normal, |r| r.0);
            return Err(ClassifierError::TooFewExamples { class, count: 0 });
        }
        let model = match scheme {
            Scheme::Tree => ClassifierModel::Tree(SvmTree::train(&rows, &svm, true)?),
            Scheme::TreeMostSeparableFirst => ClassifierModel::Tree(SvmTree::train(&rows, &svm, false)?),
            Scheme::OneVsOne => ClassifierModel::OneVsOne(OneVsOne::train(&rows, &svm)?),
        };
        Ok(Classifier {
            format: CLASSIFIER_FORMAT.to_string(),
            feature_names: FEATURE_NAMES.iter().map(|s| s.to_string()).collect(),
            features,
            svm,
            standardizer,
            model,
        })
    }

    /// The class of a (raw, unstandardised) feature vector.
    pub fn classify(&self, features: &[f64]) -> Result<FaultClass, ClassifierError> {
        if features.len() != self.standardizer.mean.len() {
            return Err(ClassifierError::FeatureCount { expected: self.standardizer.mean.len(), got: features.len() });
        }
        if !features.iter().all(|v| v.is_finite()) {
            return Err(ClassifierError::NonFiniteFeature);
        }
        let x = self.standardizer.apply(features);
        Ok(match &self.model {
            ClassifierModel::Tree(tree) => tree.classify(&x),
            ClassifierModel::OneVsOne(flat) => flat.classify(&x),
        })
    }

    /// The class of a residual window (features with the saved settings).
    pub fn classify_window(&self, window: &[ResidualSample]) -> Result<FaultClass, ClassifierError> {
        self.classify(&features(window, &self.features)?)
    }

    /// The decision tree, if this is one.
    pub fn tree(&self) -> Option<&SvmTree> {
        match &self.model {
            ClassifierModel::Tree(t) => Some(t),
            ClassifierModel::OneVsOne(_) => None,
        }
    }

    pub fn to_json(&self) -> Result<String, ClassifierError> {
        serde_json::to_string(self).map_err(|e| ClassifierError::Json(e.to_string()))
    }

    pub fn from_json(text: &str) -> Result<Self, ClassifierError> {
        let c: Classifier = serde_json::from_str(text).map_err(|e| ClassifierError::Json(e.to_string()))?;
        if c.format != CLASSIFIER_FORMAT {
            return Err(ClassifierError::Format { found: c.format });
        }
        Ok(c)
    }

    /// Writes the JSON to a temporary name beside `path`, then renames it into place.
    pub fn save(&self, path: &Path) -> Result<(), ClassifierError> {
        let io = |e: std::io::Error| ClassifierError::Io { path: path.to_path_buf(), message: e.to_string() };
        let mut temporary = path.as_os_str().to_owned();
        temporary.push(".tmp");
        std::fs::write(&temporary, self.to_json()?).map_err(io)?;
        std::fs::rename(&temporary, path).map_err(io)
    }

    pub fn load(path: &Path) -> Result<Self, ClassifierError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ClassifierError::Io { path: path.to_path_buf(), message: e.to_string() })?;
        Self::from_json(&text)
    }
}

/// Counts `[true class][predicted class]`, indexed by [`FaultClass::index`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ConfusionMatrix {
    pub counts: [[u32; CLASS_COUNT]; CLASS_COUNT],
}

impl ConfusionMatrix {
    /// The classifier's confusion matrix on `examples`; examples it cannot classify (non-finite
    /// features) are returned as a count instead.
    pub fn of(classifier: &Classifier, examples: &[Example]) -> (Self, usize) {
        let mut m = ConfusionMatrix::default();
        let mut failed = 0;
        for e in examples {
            match classifier.classify(&e.features) {
                Ok(c) => m.counts[e.class.index()][c.index()] += 1,
                Err(_) => failed += 1,
            }
        }
        (m, failed)
    }

    /// Correct over total (NaN when empty).
    pub fn accuracy(&self) -> f64 {
        let total: u32 = self.counts.iter().flatten().sum();
        let correct: u32 = (0..CLASS_COUNT).map(|i| self.counts[i][i]).sum();
        correct as f64 / total as f64
    }

    /// Recall of each class (NaN for a class with no example).
    pub fn recall(&self) -> [f64; CLASS_COUNT] {
        std::array::from_fn(|i| self.counts[i][i] as f64 / self.counts[i].iter().sum::<u32>() as f64)
    }
}

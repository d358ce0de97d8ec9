//! The multi-class schemes built from binary SVMs: the seed's bottom-up decision tree and the flat
//! one-against-one vote.

use serde::{Deserialize, Serialize};

use super::features::*;
use super::svm::*;

/// A node of the decision tree.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "node", rename_all = "snake_case")]
pub enum TreeNode {
    Leaf {
        class: FaultClass,
    },
    Split {
        svm: BinarySvm,
        /// Separability of the two groups when they were merged.
        separability: f64,
        /// Taken when `decision >= 0`.
        positive: Box<TreeNode>,
        negative: Box<TreeNode>,
    },
}

impl TreeNode {
    /// The classes below this node, sorted.
    pub fn classes(&self) -> Vec<FaultClass> {
        match self {
            TreeNode::Leaf { class } => vec![*class],
            TreeNode::Split { positive, negative, .. } => {
                let mut c = positive.classes();
                c.extend(negative.classes());
                c.sort();
                c
            }
        }
    }

    pub(super) fn classify(&self, x: &[f64]) -> FaultClass {
        match self {
            TreeNode::Leaf { class } => *class,
            TreeNode::Split { svm, positive, negative, .. } => {
                if svm.decision(x) >= 0.0 {
                    positive.classify(x)
                } else {
                    negative.classify(x)
                }
            }
        }
    }
}

/// The separability of one candidate pair of groups at one merge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairSeparability {
    pub first: Vec<FaultClass>,
    pub second: Vec<FaultClass>,
    pub separability: f64,
}

/// One bottom-up step: the pair merged (the least separable) and every candidate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Merge {
    /// Positive side of the SVM trained here.
    pub positive: Vec<FaultClass>,
    pub negative: Vec<FaultClass>,
    pub separability: f64,
    pub candidates: Vec<PairSeparability>,
}

/// The seed's bottom-up SVM decision tree (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SvmTree {
    pub root: TreeNode,
    /// In training order: the first is the least separable pair of single classes.
    pub merges: Vec<Merge>,
}

/// Standardised training rows of each class present, in class order.
pub(super) type ClassRows<'a> = Vec<(FaultClass, Vec<&'a [f64]>)>;

/// A group of classes during the bottom-up build: its classes, their pooled rows, its subtree.
pub(super) type Group<'a> = (Vec<FaultClass>, Vec<&'a [f64]>, TreeNode);

impl SvmTree {
    /// Bottom-up training on standardised rows grouped by class (module docs), merging the least
    /// separable pair first (the patent's order) or, for comparison, the most separable. Ties in
    /// separability go to the pair met first (groups in class order, merged groups where their first
    /// member was).
    pub(super) fn train(rows: &ClassRows, params: &SvmParams, least_first: bool) -> Result<Self, ClassifierError> {
        let mut groups: Vec<Group> =
            rows.iter().map(|(c, r)| (vec![*c], r.clone(), TreeNode::Leaf { class: *c })).collect();
        let mut merges = Vec::new();
        while groups.len() > 1 {
            let mut candidates = Vec::new();
            let mut best = (0, 1, if least_first { f64::INFINITY } else { f64::NEG_INFINITY });
            for i in 0..groups.len() {
                for j in i + 1..groups.len() {
                    let s = separability(&groups[i].1, &groups[j].1);
                    candidates.push(PairSeparability {
                        first: groups[i].0.clone(),
                        second: groups[j].0.clone(),
                        separability: s,
                    });
                    if (least_first && s < best.2) || (!least_first && s > best.2) {
                        best = (i, j, s);
                    }
                }
            }
            let (i, j, s) = best;
            let (negative_classes, negative_rows, negative_node) = groups.remove(j);
            let (positive_classes, positive_rows, positive_node) = groups.remove(i);
            let what = format!("tree node {positive_classes:?} vs {negative_classes:?}");
            let svm = BinarySvm::train(&positive_rows, &negative_rows, params, what)?;
            merges.push(Merge {
                positive: positive_classes.clone(),
                negative: negative_classes.clone(),
                separability: s,
                candidates,
            });
            let node = TreeNode::Split {
                svm,
                separability: s,
                positive: Box::new(positive_node),
                negative: Box::new(negative_node),
            };
            let mut classes = positive_classes;
            classes.extend(negative_classes);
            let mut pooled = positive_rows;
            pooled.extend(negative_rows);
            groups.insert(i, (classes, pooled, node));
        }
        let root = groups.pop().map(|g| g.2).expect("at least one class");
        Ok(SvmTree { root, merges })
    }

    pub fn classify(&self, x: &[f64]) -> FaultClass {
        self.root.classify(x)
    }
}

/// Flat one-against-one SVM: one binary SVM per pair of classes, majority vote; a tie goes to the class
/// with the larger sum of the decision values in its favour, then to the lower class index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OneVsOne {
    /// `(positive, negative, svm)` for every pair, in class order.
    pub machines: Vec<(FaultClass, FaultClass, BinarySvm)>,
}

impl OneVsOne {
    pub(super) fn train(rows: &ClassRows, params: &SvmParams) -> Result<Self, ClassifierError> {
        let mut machines = Vec::new();
        for (i, (a, ra)) in rows.iter().enumerate() {
            for (b, rb) in &rows[i + 1..] {
                machines.push((*a, *b, BinarySvm::train(ra, rb, params, format!("{a:?} vs {b:?}"))?));
            }
        }
        Ok(OneVsOne { machines })
    }

    pub fn classify(&self, x: &[f64]) -> FaultClass {
        let mut votes = [0u32; CLASS_COUNT];
        let mut margin = [0.0f64; CLASS_COUNT];
        for (a, b, svm) in &self.machines {
            let d = svm.decision(x);
            let (winner, m) = if d >= 0.0 { (*a, d) } else { (*b, -d) };
            votes[winner.index()] += 1;
            margin[winner.index()] += m;
        }
        let best = (0..CLASS_COUNT)
            .max_by(|&i, &j| votes[i].cmp(&votes[j]).then(margin[i].total_cmp(&margin[j])).then(j.cmp(&i)))
            .unwrap_or(0);
        FaultClass::ALL[best]
    }
}

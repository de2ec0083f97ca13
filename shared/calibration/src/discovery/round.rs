//! One round of the loop: the candidates' columns at a fit, the linearised problem they
//! form with the fitted parameters, and each candidate's scores and significance.

use crate::discovery::report::Correlate;
use crate::discovery::selection::{Design, SetFit};
use crate::discovery::significance::chi2_quantile;
use crate::discovery::{ALIAS_CORRELATION, MIN_FOLDS_IMPROVED, MIN_IDENTIFIABLE, SELECTION_LEVEL};
use crate::fit::joint_fit::JointFit;
use crate::model::{CandidateInfo, RobotModel};

/// A candidate's scores at one fit.
#[derive(Debug, Clone)]
pub(super) struct Evaluation<M: RobotModel> {
    /// Index of the candidate in its round's pool.
    pub(super) index: usize,
    pub(super) candidate: M::Candidate,
    pub(super) info: CandidateInfo,
    pub(super) columns: Vec<usize>,
    pub(super) chi2_gain: f64,
    pub(super) threshold: f64,
    pub(super) held_out_gain: f64,
    pub(super) folds_improved: usize,
    pub(super) held_out_rms: [f64; 2],
    pub(super) coefficients: Vec<f64>,
    pub(super) explained_share: f64,
    /// Smallest singular value of the candidate's unit columns after projecting out the
    /// columns it is tested on top of: 1 = new information, 0 = already in their span.
    pub(super) identifiable: f64,
    /// Labels of the candidates it can hardly be told from (filled for a selected one).
    pub(super) aliases: Vec<String>,
    /// The library candidates among those aliases, scored alike: refitted in its place
    /// when it is added, the best refit wins.
    pub(super) alternatives: Vec<Evaluation<M>>,
}

impl<M: RobotModel> Evaluation<M> {
    pub(super) fn significant(&self) -> bool {
        self.identifiable >= MIN_IDENTIFIABLE
            && self.chi2_gain >= self.threshold
            && self.held_out_gain > 0.0
            && self.folds_improved >= MIN_FOLDS_IMPROVED
    }

    pub(super) fn correlate(&self) -> Correlate {
        Correlate {
            label: self.info.label.clone(),
            signal: self.info.signal.into(),
            in_library: self.info.in_library,
            chi2_gain: self.chi2_gain,
            explained_share: self.explained_share,
            held_out_gain: self.held_out_gain,
            identifiable: self.identifiable,
            significant: self.significant(),
        }
    }
}

/// The threshold of the in-sample gain of a `k`-parameter candidate on `rows` residuals,
/// when `candidates` are tried in all.
pub fn chi2_threshold(k: usize, rows: usize, candidates: usize) -> f64 {
    let candidates = candidates.max(1) as f64;
    (k as f64 * (rows.max(2) as f64).ln()).max(chi2_quantile(SELECTION_LEVEL / candidates, k))
}

/// The candidates' columns and the linearised problem at one fit.
pub(super) struct Round<M: RobotModel> {
    pub(super) pool: Vec<M::Candidate>,
    infos: Vec<CandidateInfo>,
    /// Candidates of the model's whole pool (for the family-wise level).
    tried: usize,
    pub(super) design: Design,
    pub(super) ranges: Vec<Vec<usize>>,
}

impl<M: RobotModel> Round<M> {
    pub(super) fn new(fit: &JointFit<M>, pool: Vec<M::Candidate>) -> Self {
        let model = &fit.model;
        let columns = model.candidate_columns(&fit.problem(), &pool);
        let design = Design::new(fit, &columns);
        let infos: Vec<CandidateInfo> = pool.iter().map(|c| model.candidate_info(*c)).collect();
        let mut next = 0;
        let ranges = infos
            .iter()
            .map(|info| {
                let range: Vec<usize> = (next..next + info.dim).map(|k| design.extra(k)).collect();
                next += info.dim;
                range
            })
            .collect();
        Self {
            pool,
            infos,
            tried: model.candidates().len(),
            design,
            ranges,
        }
    }

    /// Scores of the pool's candidates `which` on top of the columns `base`.
    pub(super) fn evaluate(
        &self,
        base: &[usize],
        which: impl Iterator<Item = usize>,
    ) -> Vec<Evaluation<M>> {
        let Some(without) = self.design.fit(base) else {
            return Vec::new();
        };
        which
            .filter_map(|k| self.evaluate_one(base, &without, k))
            .collect()
    }

    fn evaluate_one(&self, base: &[usize], without: &SetFit, k: usize) -> Option<Evaluation<M>> {
        let columns = &self.ranges[k];
        if columns.iter().any(|&c| self.design.is_empty_column(c)) {
            return None;
        }
        let set: Vec<usize> = base.iter().chain(columns).copied().collect();
        let with = self.design.fit(&set)?;
        let conditional = self.design.conditional_gram(base, columns)?;
        let identifiable = conditional.symmetric_eigenvalues().min().max(0.0).sqrt();
        let gains: Vec<f64> = without
            .fold_sse
            .iter()
            .zip(&with.fold_sse)
            .map(|(a, b)| a - b)
            .collect();
        let rows = self.design.rows.max(1) as f64;
        let info = &self.infos[k];
        Some(Evaluation {
            index: k,
            candidate: self.pool[k],
            info: info.clone(),
            columns: columns.clone(),
            chi2_gain: without.sse - with.sse,
            threshold: chi2_threshold(info.dim, self.design.rows, self.tried),
            held_out_gain: gains.iter().sum(),
            folds_improved: gains.iter().filter(|g| **g > 0.0).count(),
            held_out_rms: [
                (without.held_out() / rows).sqrt(),
                (with.held_out() / rows).sqrt(),
            ],
            coefficients: with.step[base.len()..].to_vec(),
            explained_share: (without.sse - with.sse) / without.sse.max(f64::MIN_POSITIVE),
            identifiable,
            aliases: Vec::new(),
            alternatives: Vec::new(),
        })
    }

    /// The pool's candidates so alike the candidate `chosen` beyond the columns `base` that
    /// the data can hardly tell which of them acts: the multiple correlation of a
    /// one-parameter candidate's column with the other's columns is at least
    /// [`ALIAS_CORRELATION`] (pairs of multi-parameter candidates are not compared).
    pub(super) fn aliases(&self, base: &[usize], chosen: usize) -> Vec<usize> {
        let own = &self.ranges[chosen];
        (0..self.pool.len())
            .filter(|&k| k != chosen && (own.len() == 1 || self.ranges[k].len() == 1))
            .filter(|&k| {
                !self.ranges[k]
                    .iter()
                    .any(|&c| self.design.is_empty_column(c))
            })
            .filter(|&k| {
                let (single, many) = if own.len() == 1 {
                    (own[0], &self.ranges[k])
                } else {
                    (self.ranges[k][0], own)
                };
                let set: Vec<usize> = std::iter::once(single)
                    .chain(many.iter().copied())
                    .collect();
                self.design
                    .conditional_gram(base, &set)
                    .and_then(|g| {
                        let n = many.len();
                        let cross = g.view((0, 1), (1, n)).transpose();
                        let inner = g.view((1, 1), (n, n)).into_owned().cholesky()?;
                        let explained = (cross.transpose() * inner.solve(&cross))[(0, 0)];
                        Some(g[(0, 0)] > 0.0 && explained / g[(0, 0)] >= ALIAS_CORRELATION.powi(2))
                    })
                    .unwrap_or(false)
            })
            .collect()
    }

    /// `chosen` with its aliases named and the library ones among them scored on `base`.
    pub(super) fn with_aliases(&self, base: &[usize], mut chosen: Evaluation<M>) -> Evaluation<M> {
        let aliases = self.aliases(base, chosen.index);
        chosen.aliases = aliases
            .iter()
            .map(|&k| self.infos[k].label.clone())
            .collect();
        chosen.alternatives = self
            .evaluate(base, aliases.into_iter())
            .into_iter()
            .filter(|e| e.info.in_library)
            .collect();
        chosen
    }
}

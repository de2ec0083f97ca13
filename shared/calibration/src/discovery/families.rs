//! The residual loop by effect families, for models whose effects come in families of many
//! small linear terms (the harmonics of one joint angle): forward selection of whole
//! families, each ridge-regularised and kept only if it lowers the cross-validated error.
//!
//! A family is the model's candidates sharing a class and a joint or link (`periodic` on
//! joint 2, `gravity_compliance` on joint 3, `drift` of one set-up). Each step, on the
//! residual left by the families chosen so far:
//!
//! 1. **Periodogram**: the power of every harmonic of a periodic family (the cost reduction
//!    of its sine and cosine alone); the family offers the harmonics above the χ²₂ quantile
//!    of [`HARMONIC_LEVEL`] (the residual is whitened, so pure noise stays below it).
//! 2. **Score**: each family with the fitted parameters, under each ridge of
//!    [`RIDGES`] (periodic families; others unregularised), is scored by its held-out error
//!    over [`FOLDS`] random folds of the poses; the strongest ridge within
//!    [`RIDGE_TOLERANCE`] of the best stands for the family.
//! 3. **Confirm**: the best family joins the chosen set if the joint ridge step on
//!    everything chosen (fitted parameters included) lowers the held-out error by at least
//!    [`MIN_RELATIVE_GAIN`]; otherwise it is rejected and the next best is tried.
//!
//! Each chosen step gives a model: the fit moved by the joint ridge step, the families'
//! effects added at their coefficients (the effects are linear in their coefficients, and
//! the fit had converged, so the step is the refit).

use std::collections::HashMap;

use crate::fit::joint_fit::JointFit;
use crate::fit::ridge::RidgeDesign;
use crate::model::RobotModel;

/// Folds of the cross-validation (random, by pose).
pub const FOLDS: usize = 5;
/// Relative ridges tried on periodic families.
pub const RIDGES: [f64; 5] = [1e-4, 1e-3, 1e-2, 1e-1, 1.0];
/// A stronger ridge is preferred while its held-out error is within this fraction of the
/// best ridge's (the smoother of two equally good fits extrapolates better).
pub const RIDGE_TOLERANCE: f64 = 0.05;
/// Level at which a harmonic's power counts as more than noise.
pub const HARMONIC_LEVEL: f64 = 1e-3;
/// Smallest relative reduction of the held-out error that keeps a family.
pub const MIN_RELATIVE_GAIN: f64 = 2e-3;
/// Most families chosen.
pub const MAX_FAMILIES: usize = 12;

/// A periodogram of the residual along one joint angle.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Periodogram {
    /// Family label, e.g. `periodic elbow_joint`.
    pub family: String,
    /// The joint, numbered as the model numbers them.
    pub joint: Option<usize>,
    /// Harmonic numbers.
    pub harmonics: Vec<f64>,
    /// Power of each (whitened cost reduction).
    pub power: Vec<f64>,
    /// The power above which a harmonic is offered.
    pub floor: f64,
}

/// One chosen family.
#[derive(Debug, Clone)]
pub struct FamilyStep<M: RobotModel> {
    /// Family label.
    pub label: String,
    /// Class of its candidates.
    pub class: &'static str,
    /// The joint it attaches to.
    pub joint: Option<usize>,
    /// The link (or set-up) it attaches to.
    pub link: Option<String>,
    /// Its candidates, with their coefficients at this step.
    pub candidates: Vec<(M::Candidate, Vec<f64>)>,
    /// The relative ridge it was fitted with.
    pub ridge: f64,
    /// Held-out whitened sum of squares before and after it joined.
    pub held_out: [f64; 2],
    /// The model after this step.
    pub model: M,
}

/// What the loop chose.
#[derive(Debug, Clone)]
pub struct FamilySelection<M: RobotModel> {
    /// The chosen families, in order.
    pub steps: Vec<FamilyStep<M>>,
    /// Periodograms of the base fit's residual.
    pub periodograms_before: Vec<Periodogram>,
    /// Periodograms of the final residual.
    pub periodograms_after: Vec<Periodogram>,
    /// Families that were best in a round but did not win held out.
    pub rejected: Vec<String>,
}

/// A family of candidates: pool indices, and their column ranges in the design.
struct Family {
    label: String,
    class: &'static str,
    joint: Option<usize>,
    link: Option<String>,
    periodic: bool,
    members: Vec<usize>,
}

/// The χ² quantile with 2 degrees of freedom at upper tail `level`.
fn chi2_2_quantile(level: f64) -> f64 {
    -2.0 * level.ln()
}

/// A pose's fold: a hash of its index and the seed.
fn fold_of(obs: usize, seed: u64) -> usize {
    let mut z = (obs as u64).wrapping_add(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) % FOLDS as u64) as usize
}

/// Runs the loop on the converged fit `fit`; `seed` draws the folds.
pub fn select_families<M: RobotModel>(fit: &JointFit<M>, seed: u64) -> FamilySelection<M> {
    let model = &fit.model;
    let carried = model.carried();
    let pool: Vec<M::Candidate> = model
        .candidates()
        .into_iter()
        .filter(|c| !carried.contains(c))
        .collect();
    let infos: Vec<_> = pool.iter().map(|c| model.candidate_info(*c)).collect();
    let extra = model.candidate_columns(&fit.problem(), &pool);
    let mut fold_of_row = vec![0; fit.rows];
    for block in &fit.blocks {
        fold_of_row[block.row..block.row + block.dim].fill(fold_of(block.obs, seed));
    }
    let design = RidgeDesign::new(&fit.jacobian, &extra, &fit.residual, &fold_of_row, FOLDS);
    let mut ranges = Vec::with_capacity(pool.len());
    let mut next = 0;
    for info in &infos {
        ranges.push(
            (next..next + info.dim)
                .map(|k| design.extra(k))
                .collect::<Vec<usize>>(),
        );
        next += info.dim;
    }
    let mut families: Vec<Family> = Vec::new();
    let mut index: HashMap<(&'static str, Option<usize>, Option<String>), usize> = HashMap::new();
    for (k, info) in infos.iter().enumerate() {
        let key = (info.class, info.joint, info.link.clone());
        let slot = *index.entry(key).or_insert_with(|| {
            let label = match &info.harmonic {
                Some(h) => info.label.trim_end_matches(&format!(" ×{h}")).to_string(),
                None => info.label.clone(),
            };
            families.push(Family {
                label,
                class: info.class,
                joint: info.joint,
                link: info.link.clone(),
                periodic: info.harmonic.is_some(),
                members: Vec::new(),
            });
            families.len() - 1
        });
        if !ranges[k].iter().any(|&c| design.is_empty_column(c)) {
            families[slot].members.push(k);
        }
    }
    let fitted: Vec<usize> = (0..design.fitted).collect();
    let floor = chi2_2_quantile(HARMONIC_LEVEL);
    let periodograms = |d: &RidgeDesign| -> Vec<Periodogram> {
        families
            .iter()
            .filter(|f| f.periodic)
            .map(|f| Periodogram {
                family: f.label.clone(),
                joint: f.joint,
                harmonics: f
                    .members
                    .iter()
                    .filter_map(|&k| infos[k].harmonic)
                    .collect(),
                power: f.members.iter().map(|&k| d.power(&ranges[k])).collect(),
                floor,
            })
            .collect()
    };
    let periodograms_before = periodograms(&design);

    // The chosen set: columns with their ridges.
    let mut chosen_columns: Vec<usize> = fitted.clone();
    let mut chosen_ridges: Vec<f64> = vec![0.0; fitted.len()];
    let mut chosen_members: Vec<(usize, Vec<usize>)> = Vec::new();
    let mut current = design.fit(&chosen_columns, &chosen_ridges);
    let mut residual_design = design.clone();
    let mut steps = Vec::new();
    let mut rejected = Vec::new();
    let mut closed = vec![false; families.len()];
    while steps.len() < MAX_FAMILIES {
        let Some(base) = current.clone() else { break };
        let Some(local_base) = residual_design.fit(&fitted, &vec![0.0; fitted.len()]) else {
            break;
        };
        // Score every open family on the current residual.
        let mut best: Option<(f64, usize, Vec<usize>, f64)> = None;
        for (f, family) in families.iter().enumerate() {
            if closed[f] || family.members.is_empty() {
                continue;
            }
            let members: Vec<usize> = if family.periodic {
                family
                    .members
                    .iter()
                    .copied()
                    .filter(|&k| residual_design.power(&ranges[k]) > floor)
                    .collect()
            } else {
                family.members.clone()
            };
            if members.is_empty() {
                continue;
            }
            let columns: Vec<usize> = members.iter().flat_map(|&k| ranges[k].clone()).collect();
            let set: Vec<usize> = fitted.iter().chain(&columns).copied().collect();
            let ridges: &[f64] = if family.periodic { &RIDGES } else { &[0.0] };
            let scored: Vec<(f64, f64)> = ridges
                .iter()
                .filter_map(|&ridge| {
                    let lambdas: Vec<f64> = fitted
                        .iter()
                        .map(|_| 0.0)
                        .chain(columns.iter().map(|_| ridge))
                        .collect();
                    Some((ridge, residual_design.fit(&set, &lambdas)?.held_out))
                })
                .collect();
            let Some(lowest) = scored.iter().map(|s| s.1).min_by(f64::total_cmp) else {
                continue;
            };
            // The strongest ridge that does about as well as the best one.
            let Some(&(ridge, held_out)) = scored
                .iter()
                .filter(|s| s.1 <= lowest * (1.0 + RIDGE_TOLERANCE))
                .max_by(|a, b| a.0.total_cmp(&b.0))
            else {
                continue;
            };
            let gain = local_base.held_out - held_out;
            if best.as_ref().is_none_or(|b| gain > b.0) {
                best = Some((gain, f, members.clone(), ridge));
            }
        }
        let Some((gain, f, members, ridge)) = best else {
            break;
        };
        if gain <= 0.0 {
            break;
        }
        // Confirm with the joint step on everything chosen.
        let columns: Vec<usize> = members.iter().flat_map(|&k| ranges[k].clone()).collect();
        let mut set = chosen_columns.clone();
        set.extend(&columns);
        let mut lambdas = chosen_ridges.clone();
        lambdas.extend(columns.iter().map(|_| ridge));
        let confirmed = design
            .fit(&set, &lambdas)
            .filter(|with| with.held_out < base.held_out * (1.0 - MIN_RELATIVE_GAIN));
        closed[f] = true;
        let Some(with) = confirmed else {
            rejected.push(families[f].label.clone());
            continue;
        };
        chosen_columns = set;
        chosen_ridges = lambdas;
        chosen_members.push((f, members));
        let stepped = stepped_model(
            fit,
            &pool,
            &ranges,
            &chosen_members,
            &chosen_columns,
            &with.step,
        );
        let family = &families[f];
        let last = &chosen_members[chosen_members.len() - 1].1;
        steps.push(FamilyStep {
            label: family.label.clone(),
            class: family.class,
            joint: family.joint,
            link: family.link.clone(),
            candidates: last
                .iter()
                .map(|&k| {
                    (
                        pool[k],
                        coefficients(&ranges[k], &chosen_columns, &with.step),
                    )
                })
                .collect(),
            ridge,
            held_out: [base.held_out, with.held_out],
            model: stepped,
        });
        residual_design = match design.after(&chosen_columns, &chosen_ridges) {
            Some(d) => d,
            None => break,
        };
        current = Some(with);
    }
    FamilySelection {
        periodograms_after: periodograms(&residual_design),
        periodograms_before,
        steps,
        rejected,
    }
}

/// The step's values on `columns` (positions looked up in the chosen set).
fn coefficients(columns: &[usize], chosen: &[usize], step: &[f64]) -> Vec<f64> {
    columns
        .iter()
        .map(|c| chosen.iter().position(|x| x == c).map_or(0.0, |k| step[k]))
        .collect()
}

/// The fit's model moved by the joint step: fitted parameters shifted, chosen effects added
/// at their coefficients.
fn stepped_model<M: RobotModel>(
    fit: &JointFit<M>,
    pool: &[M::Candidate],
    ranges: &[Vec<usize>],
    chosen: &[(usize, Vec<usize>)],
    columns: &[usize],
    step: &[f64],
) -> M {
    let mut model = fit.model.clone();
    for (k, id) in fit.layout.ids.iter().enumerate() {
        model.set(*id, model.get(*id) + step[k]);
    }
    for (_, members) in chosen {
        for &k in members {
            let _ = model.add_effect(pool[k], &coefficients(&ranges[k], columns, step));
        }
    }
    model
}

//! Building a [`KinematicTree`] from link and joint specifications: one root, every link
//! reached once, joints in topological order, mimic joints resolved to the variable that
//! drives them.

use std::collections::{HashMap, VecDeque};

use nalgebra::Unit;

use super::geometric::joint_error_parameters;
use super::{
    Drive, JointSpec, JointType, JointVariable, KinematicTree, LinkSpec, TreeError, TreeJoint,
    TreeLink,
};

impl KinematicTree {
    /// Builds the tree named `name` from its links and joints (in any order), checking that
    /// they form one tree with valid axes, limits, inertials and mimic references.
    pub fn new(
        name: impl Into<String>,
        links: Vec<LinkSpec>,
        joints: Vec<JointSpec>,
    ) -> Result<Self, TreeError> {
        let link_names = index_links(&links)?;
        let parent_of = parent_joints(&joints, &link_names)?;
        let roots: Vec<usize> = (0..links.len())
            .filter(|link| !parent_of.contains_key(link))
            .collect();
        let [root] = roots[..] else {
            let names = roots.iter().map(|&i| links[i].name.clone()).collect();
            return Err(TreeError::Roots(names));
        };
        let order = topological_order(root, &links, &joints, &link_names)?;
        for &index in &order {
            check_joint(&joints[index])?;
        }
        let position_of: HashMap<&str, usize> = order
            .iter()
            .enumerate()
            .map(|(position, &index)| (joints[index].name.as_str(), position))
            .collect();

        let mut variables = Vec::new();
        for (position, &index) in order.iter().enumerate() {
            let spec = &joints[index];
            if spec.kind != JointType::Fixed && spec.mimic.is_none() {
                variables.push(JointVariable {
                    name: spec.name.clone(),
                    joint: position,
                    kind: spec.kind,
                    limits: spec.limits,
                });
            }
        }
        let mut tree_joints = Vec::with_capacity(order.len());
        let mut errors = Vec::new();
        for (position, &index) in order.iter().enumerate() {
            let spec = &joints[index];
            let drive = match spec.kind {
                JointType::Fixed => None,
                _ => Some(resolve_drive(
                    spec,
                    &joints,
                    &order,
                    &position_of,
                    &variables,
                )?),
            };
            let first_error = drive.map(|_| {
                let first = errors.len();
                errors.extend(joint_error_parameters(&spec.name, position));
                first
            });
            tree_joints.push(TreeJoint {
                name: spec.name.clone(),
                parent_link: link_names[spec.parent.as_str()],
                child_link: link_names[spec.child.as_str()],
                origin: spec.origin,
                kind: spec.kind,
                axis: Unit::new_normalize(spec.axis),
                limits: spec.limits,
                drive,
                first_error,
            });
        }

        let mut tree_links: Vec<TreeLink> = links
            .iter()
            .map(|spec| TreeLink {
                name: spec.name.clone(),
                parent_joint: None,
                inertial: spec.inertial,
            })
            .collect();
        let mut chains = vec![Vec::new(); links.len()];
        for (position, joint) in tree_joints.iter().enumerate() {
            tree_links[joint.child_link].parent_joint = Some(position);
            let mut chain = chains[joint.parent_link].clone();
            if joint.drive.is_some() {
                chain.push(position);
            }
            chains[joint.child_link] = chain;
        }
        Ok(KinematicTree {
            name: name.into(),
            links: tree_links,
            joints: tree_joints,
            variables,
            errors,
            chains,
            root,
            link_names: link_names
                .into_iter()
                .map(|(name, index)| (name.to_owned(), index))
                .collect(),
        })
    }
}

/// Link name → index; refuses duplicate names and bad inertials.
fn index_links(links: &[LinkSpec]) -> Result<HashMap<&str, usize>, TreeError> {
    let mut names = HashMap::with_capacity(links.len());
    for (index, link) in links.iter().enumerate() {
        if names.insert(link.name.as_str(), index).is_some() {
            return Err(TreeError::DuplicateLink(link.name.clone()));
        }
        if let Some(inertial) = link.inertial {
            let valid = inertial.mass_kg.is_finite()
                && inertial.mass_kg >= 0.0
                && inertial.centre_of_mass_mm.iter().all(|v| v.is_finite());
            if !valid {
                return Err(TreeError::BadInertial(link.name.clone()));
            }
        }
    }
    Ok(names)
}

/// Child link index → index of its parent joint; refuses unknown links, duplicate joint
/// names and links with two parents.
fn parent_joints(
    joints: &[JointSpec],
    link_names: &HashMap<&str, usize>,
) -> Result<HashMap<usize, usize>, TreeError> {
    let mut joint_names = HashMap::with_capacity(joints.len());
    let mut parent_of = HashMap::with_capacity(joints.len());
    for (index, joint) in joints.iter().enumerate() {
        if joint_names.insert(joint.name.as_str(), index).is_some() {
            return Err(TreeError::DuplicateJoint(joint.name.clone()));
        }
        let link = |role, name: &str| {
            link_names
                .get(name)
                .copied()
                .ok_or_else(|| TreeError::UnknownLink {
                    joint: joint.name.clone(),
                    role,
                    link: name.to_owned(),
                })
        };
        link("parent", &joint.parent)?;
        let child = link("child", &joint.child)?;
        if let Some(first) = parent_of.insert(child, index) {
            return Err(TreeError::TwoParents {
                link: joint.child.clone(),
                first: joints[first].name.clone(),
                second: joint.name.clone(),
            });
        }
    }
    Ok(parent_of)
}

/// Joint indices in breadth-first order from `root`; every link must be reached.
fn topological_order(
    root: usize,
    links: &[LinkSpec],
    joints: &[JointSpec],
    link_names: &HashMap<&str, usize>,
) -> Result<Vec<usize>, TreeError> {
    let mut children: HashMap<usize, Vec<usize>> = HashMap::new();
    for (index, joint) in joints.iter().enumerate() {
        children
            .entry(link_names[joint.parent.as_str()])
            .or_default()
            .push(index);
    }
    let mut reached = vec![false; links.len()];
    reached[root] = true;
    let mut order = Vec::with_capacity(joints.len());
    let mut queue = VecDeque::from([root]);
    while let Some(link) = queue.pop_front() {
        for &joint in children.get(&link).map(Vec::as_slice).unwrap_or_default() {
            let child = link_names[joints[joint].child.as_str()];
            reached[child] = true;
            order.push(joint);
            queue.push_back(child);
        }
    }
    match reached.iter().position(|&r| !r) {
        Some(link) => Err(TreeError::Disconnected(links[link].name.clone())),
        None => Ok(order),
    }
}

/// Checks a joint's origin, axis and limits.
fn check_joint(joint: &JointSpec) -> Result<(), TreeError> {
    let bad = |reason: String| TreeError::BadJoint {
        joint: joint.name.clone(),
        reason,
    };
    let origin = joint.origin.to_homogeneous();
    if !origin.iter().all(|v| v.is_finite()) {
        return Err(bad("the origin is not finite".into()));
    }
    if joint.kind == JointType::Fixed {
        return Ok(());
    }
    let norm = joint.axis.norm();
    if !(norm.is_finite() && norm > 1e-12) {
        return Err(TreeError::BadAxis(joint.name.clone()));
    }
    if let Some(limits) = joint.limits {
        if limits.lower.is_nan() || limits.upper.is_nan() || limits.lower >= limits.upper {
            return Err(bad(format!(
                "the limits [{}, {}] {} are empty (a revolute joint without limits is `continuous`)",
                limits.lower,
                limits.upper,
                joint.kind.unit()
            )));
        }
    }
    if let Some(mimic) = &joint.mimic {
        if !(mimic.multiplier.is_finite() && mimic.offset.is_finite()) {
            return Err(bad("the mimic multiplier and offset must be finite".into()));
        }
    }
    Ok(())
}

/// The variable that drives the moving joint `spec`, following mimic references (composing
/// multipliers and offsets) to an independent joint.
fn resolve_drive(
    spec: &JointSpec,
    joints: &[JointSpec],
    order: &[usize],
    position_of: &HashMap<&str, usize>,
    variables: &[JointVariable],
) -> Result<Drive, TreeError> {
    let mut drive = Drive {
        variable: 0,
        multiplier: 1.0,
        offset: 0.0,
    };
    let mut current = spec;
    for _ in 0..=joints.len() {
        let Some(mimic) = &current.mimic else {
            drive.variable = variables
                .iter()
                .position(|v| v.name == current.name)
                .expect("an independent moving joint is a variable");
            return Ok(drive);
        };
        let bad = |reason| TreeError::BadMimic {
            joint: spec.name.clone(),
            mimicked: mimic.joint.clone(),
            reason,
        };
        let &position = position_of
            .get(mimic.joint.as_str())
            .ok_or_else(|| bad("no such joint"))?;
        let next = &joints[order[position]];
        if next.kind == JointType::Fixed {
            return Err(bad("it is a fixed joint"));
        }
        // value = m1 · (m2 · q + o2) + o1
        drive.offset += drive.multiplier * mimic.offset;
        drive.multiplier *= mimic.multiplier;
        current = next;
    }
    Err(TreeError::BadMimic {
        joint: spec.name.clone(),
        mimicked: spec
            .mimic
            .as_ref()
            .map(|m| m.joint.clone())
            .unwrap_or_default(),
        reason: "the mimic references form a loop",
    })
}

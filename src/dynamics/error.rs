//! Errors of model building and of the checked algorithm entry points.

/// Everything that can go wrong in `dynamics`: each variant names the offending item.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum DynamicsError {
    #[error("cannot read URDF {path}: {reason}")]
    Io { path: String, reason: String },
    #[error("malformed URDF: {0}")]
    Parse(String),
    #[error(
        "joint '{joint}' has unsupported type '{kind}' (supported: revolute, continuous, prismatic, fixed)"
    )]
    UnsupportedJointType { joint: String, kind: String },
    #[error("joint '{joint}' names {role} link '{link}', which does not exist")]
    MissingLink {
        joint: String,
        role: &'static str,
        link: String,
    },
    #[error("link '{link}' is the child of two joints ('{first}' and '{second}')")]
    MultipleParents {
        link: String,
        first: String,
        second: String,
    },
    #[error("kinematic cycle through link '{link}'")]
    Cycle { link: String },
    #[error("URDF has no root link (every link is a child: the graph is cyclic)")]
    NoRoot,
    #[error("URDF has several root links: {0}")]
    MultipleRoots(String),
    #[error("URDF has no links")]
    Empty,
    #[error("duplicate {what} name '{name}'")]
    DuplicateName { what: &'static str, name: String },
    #[error("link '{link}' has an invalid inertia: {reason}")]
    InvalidInertia { link: String, reason: String },
    #[error("joint '{joint}' is invalid: {reason}")]
    InvalidJoint { joint: String, reason: String },
    #[error("{what} has length {got}, the model needs {expected}")]
    DimensionMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{what} contains a non-finite value at index {index}")]
    NonFinite { what: &'static str, index: usize },
    #[error("no frame named '{0}'")]
    UnknownFrame(String),
    #[error("no joint named '{0}'")]
    UnknownJoint(String),
    #[error("'{root}' is not a moving ancestor of frame '{frame}' (empty or invalid sub-chain)")]
    NotAnAncestor { root: String, frame: String },
    #[error("{0} is singular or not positive definite")]
    Singular(&'static str),
    #[error(
        "forward dynamics is singular at joint '{joint}' (zero articulated inertia about its axis: a massless terminal body?)"
    )]
    SingularJoint { joint: String },
}

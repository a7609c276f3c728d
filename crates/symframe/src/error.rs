//! Errors of the core library.

/// What can go wrong when building a rig or running the estimator on a stack.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum Error {
    /// The rig has no lights at all.
    #[error("no lights were given")]
    NoLights,
    /// A light direction is zero or not finite (index into the input list).
    #[error("light {index} is zero or not finite")]
    BadLight {
        /// Index of the light in the input list.
        index: usize,
    },
    /// Every light is outside the measured cone `theta_d < theta_d_max`.
    #[error(
        "all {n_lights} lights are outside the light cone (theta_d < {theta_d_max_deg} degrees, \
         i.e. within {} degrees of the view): widen the cone or check the light file's frame",
        2.0 * theta_d_max_deg
    )]
    AllLightsOutsideCone {
        /// Number of lights given.
        n_lights: usize,
        /// The cone's half-angle in halfway space, degrees.
        theta_d_max_deg: f64,
    },
    /// Too few lights remain inside the cone to triangulate the slice.
    #[error("only {used} lights are inside the light cone; at least 3 are needed")]
    TooFewLights {
        /// Lights inside the cone.
        used: usize,
    },
    /// The stack's light count does not match the rig's.
    #[error("the stack has {stack} images but the rig has {rig} lights")]
    LightCountMismatch {
        /// Images in the stack.
        stack: usize,
        /// Lights in the rig.
        rig: usize,
    },
    /// A mask of the wrong size, or one with no pixel inside.
    #[error("{0}")]
    BadMask(String),
    /// A parameter is out of its valid range.
    #[error("invalid parameter: {0}")]
    BadParameter(String),
}

/// Result alias of the core library.
pub type Result<T> = std::result::Result<T, Error>;

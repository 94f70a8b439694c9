//! A scenario's reference: the segments of the motion the device is asked for.

use super::*;

/// The reference trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reference {
    /// The segments, in order.
    pub segments: Vec<SegmentSpec>,
}

/// One reference segment as written in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum SegmentSpec {
    /// Rest.
    Hold {
        /// \[s\]
        duration: f32,
    },
    /// One step.
    Step {
        /// \[rad\]
        distance: f32,
        /// \[s\]
        dwell: f32,
    },
    /// Jerk-limited moves of the given numbers of encoder counts, each followed by a dwell.
    Steps {
        /// Step sizes \[counts\].
        counts: Vec<i64>,
        /// Rest after each move \[s\].
        dwell: f32,
        /// Speed limit [rad/s].
        #[serde(default = "default_vmax")]
        vmax: f32,
        /// Acceleration limit [rad/s^2].
        #[serde(default = "default_amax")]
        amax: f32,
        /// Jerk limit [rad/s^3].
        #[serde(default = "default_jmax")]
        jmax: f32,
    },
    /// Equal steps.
    Staircase {
        /// \[rad\]
        distance: f32,
        /// Number of steps.
        count: u32,
        /// \[s\]
        dwell: f32,
    },
    /// x = A (1 - cos 2 pi f t).
    Sine {
        /// \[rad\]
        amplitude: f32,
        /// \[Hz\]
        freq: f32,
        /// Periods.
        cycles: f32,
    },
    /// Jerk-limited move.
    Move {
        /// \[rad\]
        distance: f32,
        /// [rad/s]
        vmax: f32,
        /// [rad/s^2]
        amax: f32,
        /// [rad/s^3]
        jmax: f32,
        /// \[s\]
        dwell: f32,
    },
}
pub(super) fn default_vmax() -> f32 {
    0.5
}
pub(super) fn default_amax() -> f32 {
    50.0
}
pub(super) fn default_jmax() -> f32 {
    1e4
}

/// The most segments a reference may expand to.
pub const MAX_SEGMENTS: usize = 64;

//! Orthophotos in the site frame.

use serde::{Deserialize, Serialize};

use super::{Grid, PodVec};

/// An RGB orthophoto on a north-up grid in the site frame, row-major from the north-west corner.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ortho {
    /// Where the pixels are.
    pub grid: Grid,
    /// 8-bit RGB per cell.
    pub rgb: PodVec<[u8; 3]>,
    /// 1 where the cell was observed, 0 where it is outside the source image.
    pub valid: PodVec<u8>,
}

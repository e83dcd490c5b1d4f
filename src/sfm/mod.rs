//! Structure from motion: keypoints and descriptors (`features`), matching (`matching`) and
//! two-view geometry (`two_view`).

pub mod features;
pub mod matching;
pub mod two_view;

//! Structure from motion: keypoints and descriptors (`features`), matching (`matching`),
//! two-view geometry (`two_view`) and bundle adjustment (`bundle`).

pub mod bundle;
pub mod eval;
pub mod features;
pub mod mapper;
pub mod matching;
pub mod pnp;
pub mod tracks;
pub mod two_view;

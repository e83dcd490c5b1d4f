//! Camera calibration from chessboard images.

pub mod detect;

//! Discrete signed distance grids (in progress).

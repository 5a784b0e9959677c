//! Fast 3x3 SVD (placeholder, being written).

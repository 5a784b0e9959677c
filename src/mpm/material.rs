//! Constitutive models (placeholder, being written).

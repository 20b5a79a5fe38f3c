//! Joint mean-field inference (paper §3, Algorithm 1). (Being implemented.)

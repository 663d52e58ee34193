//! The world model (paper §3, §4.1): scalar maths through `libm` and seed derivation
//! ([`math`]), SE(2) conventions ([`geometry`]), the polygonal floor plan with ray casting
//! and the topological scan ([`floorplan`]), and rotational-symmetry detection
//! ([`symmetry`]). Imports only [`crate::limits`].

pub mod floorplan;
pub mod geometry;
pub mod math;
pub mod symmetry;

//! The world model (paper §3, §4.1): scalar maths through `libm` and seed derivation
//! ([`math`]; libm's sine and cosine in fixed point for the M4F, [`trig`]), SE(2)
//! conventions ([`geometry`]), the polygonal floor plan with ray casting and the
//! topological scan ([`floorplan`]; visibility from one viewpoint to many, [`sightlines`]),
//! and rotational-symmetry detection ([`symmetry`]).
//! Imports only [`crate::limits`].

pub mod floorplan;
pub mod geometry;
pub mod math;
pub mod sightlines;
pub mod symmetry;
pub mod trig;

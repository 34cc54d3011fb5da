//! # hils-plant: the railway brake plant of the HILS
//!
//! A `no_std`, allocation-free, panic-free model of one intercity railcar braking on a
//! straight rail (Lee & Kang 2015, PLoS ONE 10(8): e0135459): a 17-DOF vehicle
//! ([`plant`]), Polach wheel-rail contact ([`contact`], Eqs 9-12), brake torque
//! ([`brake`], Eq 1), variable disc-pad friction ([`friction`], Eq 2) and the lumped disc
//! heat balance ([`thermal`], Eqs 3-6). Generic over [`Real`] (f32 on the target, f32 and
//! f64 on the host: one copy of the physics, checked in both precisions); every
//! transcendental function comes from [`math`], the one place that picks the math
//! implementation for every build.
#![no_std]
#![forbid(unsafe_code)]

#[cfg(test)]
extern crate std;

pub mod brake;
pub mod contact;
pub mod friction;
pub mod keys;
pub mod math;
pub mod params;
pub mod plant;
pub mod real;
pub mod thermal;
pub mod track;
pub mod tracked;

pub use params::{FrictionModel, ParamError, Params, Rail, STEP_S};
pub use plant::{BrakeInput, Energy, Flags, Outputs, Plant, WHEELSETS, WheelsetOutput};
pub use real::Real;
pub use track::{DegradedAdhesionParams, Surface, Track, TrackAdhesion, Zone};

//! Learning an active sparse-sampling policy (paper §3.1): the actor-critic network that
//! decides, from the localizer's belief map and a few side features, whether to rotate left,
//! rotate right or measure ([`net`], hand-written f32 forward and backward so training runs on
//! a couple of CPU cores without a deep-learning framework and the same layer maths can later
//! be ported to the Cortex-M4); the versioned, checksummed policy file that carries a trained
//! network from the trainer to the evaluator and the firmware ([`file`](mod@file)); the agent
//! that plays a network behind the core's `Policy` seam ([`agent`]); the A2C trainer
//! ([`train`]) and its hyper-parameters, each default written once ([`hyper`]); and the
//! post-training int8 quantisation into the blob the instrument runs ([`quantize`]).

pub mod agent;
pub mod file;
pub mod hyper;
pub mod net;
pub mod quantize;
pub mod train;

//! Learning an active sparse-sampling policy: the actor-critic network that decides, from the
//! localizer's belief map and a few side features, whether to rotate left, rotate right or
//! measure ([`net`], hand-written f32 forward and backward so training runs on a couple of
//! CPU cores without a deep-learning framework and the same layer maths can later be ported
//! to the Cortex-M4), and the versioned, checksummed policy file that carries a trained
//! network from the trainer to the evaluator and the firmware ([`file`](mod@file)).

pub mod file;
pub mod net;

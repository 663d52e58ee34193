//! The learnt policy as the instrument plays it (paper §3.1): the actor-critic network that
//! decides, from the localizer's belief map and a few side features, whether to rotate left,
//! rotate right or measure ([`net`], hand-written f32 forward and backward so training runs on
//! a couple of CPU cores without a deep-learning framework); the versioned, checksummed policy
//! file that carries a trained network from the trainer to the evaluator and the firmware
//! ([`file`](mod@file)); and the agents that play behind the core's `Policy` seam, with the
//! one dispatch from an agent's name to its episode ([`agent`]). Training and int8
//! quantisation are the lab's (`activesense-lab`).

pub mod agent;
pub mod file;
pub mod net;

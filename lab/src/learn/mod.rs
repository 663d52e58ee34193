//! Making the learnt policy (paper §3.1, §4.2): the A2C/PPO trainer ([`train`]), its
//! hyper-parameters, each default written once ([`hyper`]), and its record ([`log`]); and the post-training int8
//! quantisation into the blob the instrument runs ([`quantize`]). The network, the policy
//! file and the agent are the instrument's (`activesense_instrument::learn`).

pub mod hyper;
pub mod log;
pub mod quantize;
pub mod train;

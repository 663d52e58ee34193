//! The drawings a user looks at on the instrument side: the plan and one episode's scene
//! ([`svg`]). The lab's charts (budget, utility, learning curves) are in `activesense-lab`.

pub mod svg;

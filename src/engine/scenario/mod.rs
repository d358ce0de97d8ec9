//! From a deck to a trial's scenario: the decks' common sections and their validation, the design of a
//! sensitivity study, the per-trial random streams and noise generator, and the draws every kind shares.

pub mod deck;
pub mod design;
pub mod draws;
pub mod noise;
pub mod profile_grid;
pub mod streams;

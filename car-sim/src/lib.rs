//! A simulated car / HIL board that speaks the car protocol.

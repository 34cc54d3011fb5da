//! Shared helpers of the host integration tests (`tests/`).

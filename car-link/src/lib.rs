//! The car's wire protocol, its transports and an async client.

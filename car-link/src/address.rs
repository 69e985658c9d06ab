//! Car addresses as URLs: `tcp://host:8300`, `udp://host:8300`, `serial:///dev/ttyACM0`, `sim`
//! and `sitl:TREE` (a firmware tree built for the host).

use std::fmt;
use std::str::FromStr;

use thiserror::Error;

/// The bridge's default TCP and UDP port.
pub const DEFAULT_PORT: u16 = 8300;

/// Where a car is reached.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum CarAddress {
    /// The reference bridge over TCP (one client at a time).
    Tcp {
        /// Host name or IP address.
        host: String,
        /// TCP port (default 8300).
        port: u16,
    },
    /// The reference bridge over UDP: one payload per datagram, replies to `port + 1`.
    Udp {
        /// Host name or IP address.
        host: String,
        /// The bridge's UDP port (default 8300); the client listens on `port + 1`.
        port: u16,
    },
    /// A controller board's USB serial port (CDC ACM).
    Serial {
        /// Device path, e.g. `/dev/ttyACM0`.
        path: String,
    },
    /// The embedded simulated car; the orchestrator resolves it and hands car-link a stream.
    Sim,
    /// The car's own firmware, built from a firmware tree for the host and run in virtual time
    /// (`docs/sitl.md`); the orchestrator builds and starts it and hands car-link a stream.
    Sitl {
        /// The tree's `Embedded/RC_Controller` folder, as given.
        tree: String,
    },
}

/// A car address that does not parse.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AddressError {
    /// Not one of the known schemes.
    #[error(
        "car address {0:?}: expected tcp://host[:port], udp://host[:port], serial:///dev/…, sim or sitl:FIRMWARE_TREE"
    )]
    Scheme(String),
    /// No host after the scheme.
    #[error("car address {0:?} has no host")]
    NoHost(String),
    /// A port that is not a number in 1..=65535 (UDP: ..=65534, since replies come to port + 1).
    #[error("car address {address:?}: bad port {port:?}")]
    Port {
        /// The address.
        address: String,
        /// The port text.
        port: String,
    },
    /// A serial address without a device path.
    #[error("car address {0:?} has no device path")]
    NoPath(String),
    /// A `sitl:` address without a firmware tree.
    #[error("car address {0:?} names no firmware tree (sitl:path/to/Embedded/RC_Controller)")]
    NoTree(String),
}

fn host_port(address: &str, rest: &str, max_port: u16) -> Result<(String, u16), AddressError> {
    let rest = rest.trim_end_matches('/');
    let (host, port) = match rest.rsplit_once(':') {
        // An IPv6 literal is bracketed: [::1]:8300.
        Some((host, port)) if !host.is_empty() && (!host.contains(':') || host.ends_with(']')) => {
            let parsed = port
                .parse::<u16>()
                .ok()
                .filter(|p| (1..=max_port).contains(p));
            let port = parsed.ok_or_else(|| AddressError::Port {
                address: address.into(),
                port: port.into(),
            })?;
            (host, port)
        }
        _ => (rest, DEFAULT_PORT),
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() {
        return Err(AddressError::NoHost(address.into()));
    }
    Ok((host.to_string(), port))
}

impl FromStr for CarAddress {
    type Err = AddressError;

    fn from_str(address: &str) -> Result<Self, Self::Err> {
        let address = address.trim();
        if address == "sim" || address == "sim://" {
            return Ok(CarAddress::Sim);
        }
        if let Some(rest) = address.strip_prefix("tcp://") {
            let (host, port) = host_port(address, rest, u16::MAX)?;
            return Ok(CarAddress::Tcp { host, port });
        }
        if let Some(rest) = address.strip_prefix("udp://") {
            let (host, port) = host_port(address, rest, u16::MAX - 1)?;
            return Ok(CarAddress::Udp { host, port });
        }
        if let Some(tree) = address.strip_prefix("sitl:") {
            let tree = tree.strip_prefix("//").unwrap_or(tree);
            if tree.is_empty() {
                return Err(AddressError::NoTree(address.into()));
            }
            return Ok(CarAddress::Sitl { tree: tree.into() });
        }
        if let Some(path) = address.strip_prefix("serial://") {
            if path.is_empty() {
                return Err(AddressError::NoPath(address.into()));
            }
            return Ok(CarAddress::Serial { path: path.into() });
        }
        Err(AddressError::Scheme(address.into()))
    }
}

impl fmt::Display for CarAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bracket = |host: &str| {
            if host.contains(':') {
                format!("[{host}]")
            } else {
                host.to_string()
            }
        };
        match self {
            CarAddress::Tcp { host, port } => write!(f, "tcp://{}:{port}", bracket(host)),
            CarAddress::Udp { host, port } => write!(f, "udp://{}:{port}", bracket(host)),
            CarAddress::Serial { path } => write!(f, "serial://{path}"),
            CarAddress::Sim => f.write_str("sim"),
            CarAddress::Sitl { tree } => write!(f, "sitl:{tree}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<CarAddress, AddressError> {
        s.parse()
    }

    #[test]
    fn parses_every_scheme() {
        assert_eq!(
            parse("tcp://car1:8300"),
            Ok(CarAddress::Tcp {
                host: "car1".into(),
                port: 8300
            })
        );
        assert_eq!(
            parse("tcp://10.0.0.5"),
            Ok(CarAddress::Tcp {
                host: "10.0.0.5".into(),
                port: 8300
            })
        );
        assert_eq!(
            parse("udp://10.0.0.5:9000"),
            Ok(CarAddress::Udp {
                host: "10.0.0.5".into(),
                port: 9000
            })
        );
        assert_eq!(
            parse("serial:///dev/ttyACM0"),
            Ok(CarAddress::Serial {
                path: "/dev/ttyACM0".into()
            })
        );
        assert_eq!(parse("sim"), Ok(CarAddress::Sim));
        assert_eq!(
            parse("sitl:../fw/Embedded/RC_Controller"),
            Ok(CarAddress::Sitl {
                tree: "../fw/Embedded/RC_Controller".into()
            })
        );
        assert_eq!(
            parse("sitl:///abs/tree").map(|a| a.to_string()),
            Ok("sitl:/abs/tree".into())
        );
        assert_eq!(parse("sitl:"), Err(AddressError::NoTree("sitl:".into())));
        assert_eq!(
            parse("tcp://[::1]:8300"),
            Ok(CarAddress::Tcp {
                host: "::1".into(),
                port: 8300
            })
        );
    }

    #[test]
    fn rejects_bad_addresses() {
        assert!(matches!(parse("http://car"), Err(AddressError::Scheme(_))));
        assert!(matches!(
            parse("tcp://car:0"),
            Err(AddressError::Port { .. })
        ));
        assert!(matches!(
            parse("tcp://car:x"),
            Err(AddressError::Port { .. })
        ));
        assert!(matches!(
            parse("udp://car:65535"),
            Err(AddressError::Port { .. })
        ));
        assert!(matches!(parse("tcp://"), Err(AddressError::NoHost(_))));
        assert!(matches!(parse("serial://"), Err(AddressError::NoPath(_))));
    }

    #[test]
    fn display_round_trips() {
        for text in [
            "tcp://car1:8300",
            "udp://10.0.0.5:9000",
            "serial:///dev/ttyACM0",
            "sim",
            "tcp://[::1]:8300",
        ] {
            assert_eq!(parse(text).map(|a| a.to_string()), Ok(text.to_string()));
        }
    }
}

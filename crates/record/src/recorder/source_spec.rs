//! Where a recording's messages come from, in the two spellings a field engineer writes:
//!
//! - a command-line spec, `KIND:ARGS` ([`SourceSpec::from_str`]; the `record` flags are
//!   the same specs without the kind: `--serial /dev/ttyACM0:115200:ubx` is
//!   `serial:/dev/ttyACM0:115200:ubx`):
//!   `udp:PORT`, `tcp:PORT[:FORMAT]`, `tcp-client:HOST:PORT[:FORMAT]`,
//!   `serial:DEVICE:BAUD[:FORMAT]`, `file:PATH[:FORMAT]`, `stdin[:FORMAT]`,
//!   `simulate[:SCENARIO]`, and the vehicle's CAN bus, `can:ADAPTER` (see [`CanAdapter`]);
//! - a `[[source]]` table of a sources file (`udp = 5600`, or `serial = "/dev/ttyACM0"` with
//!   `baud = 115200`, `format = "ubx"`, `topic = "/gnss/rx2"`), deserialised directly.
//!
//! FORMAT is `json`, `nmea` or `ubx`, optionally `FORMAT=/topic` (or `=/topic`) to send a
//! receiver's fixes to their own channel. Network listeners bind 127.0.0.1 until
//! [`SourceSpec::bind`] says otherwise.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::Deserialize;

use super::stream::StreamFormat;

/// What is wrong with a source spec.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    #[error("{spec}: {what}")]
    Bad { spec: String, what: String },
    #[error("give exactly one of udp, tcp, tcp_client, serial, file, stdin, simulate, can")]
    Kinds,
    #[error("serial needs baud")]
    NoBaud,
}

fn bad(spec: &str, what: impl Into<String>) -> SpecError {
    SpecError::Bad {
        spec: spec.to_owned(),
        what: what.into(),
    }
}

/// Where messages come from.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "SourceTable")]
pub enum SourceSpec {
    /// JSON lines in UDP datagrams.
    Udp { addr: SocketAddr },
    /// A TCP listener; each connection a stream of the given format.
    TcpListen {
        addr: SocketAddr,
        format: StreamFormat,
        topic: Option<String>,
    },
    /// A TCP connection to a receiver or gateway, retried with backoff when it drops.
    TcpClient {
        addr: String,
        format: StreamFormat,
        topic: Option<String>,
    },
    Stdin {
        format: StreamFormat,
        topic: Option<String>,
    },
    File {
        path: PathBuf,
        format: StreamFormat,
        topic: Option<String>,
    },
    /// A serial device (8N1 at `baud`), reopened with backoff when it
    /// goes away (a USB receiver unplugged).
    Serial {
        path: PathBuf,
        baud: u32,
        format: StreamFormat,
        topic: Option<String>,
    },
    /// The vehicle's CAN bus through an adapter, each frame logged whole and, with the
    /// vehicle's DBC, decoded.
    Can {
        adapter: CanAdapter,
        dbc: Option<std::sync::Arc<railfuse_can::dbc::Database>>,
    },
    /// The embedded simulator, played out in real time (or `speed` times faster).
    Simulated {
        scenario: String,
        seed: u64,
        speed: f64,
        duration_s: Option<f64>,
    },
}

fn to(topic: &Option<String>) -> String {
    topic.as_ref().map_or(String::new(), |t| format!(" → {t}"))
}

impl std::fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SourceSpec::Udp { addr } => write!(f, "udp {addr} (json)"),
            SourceSpec::TcpListen {
                addr,
                format,
                topic,
            } => write!(f, "tcp listen {addr} ({format:?}{})", to(topic)),
            SourceSpec::TcpClient {
                addr,
                format,
                topic,
            } => write!(f, "tcp {addr} ({format:?}{})", to(topic)),
            SourceSpec::Stdin { format, topic } => write!(f, "stdin ({format:?}{})", to(topic)),
            SourceSpec::File {
                path,
                format,
                topic,
            } => write!(f, "file {} ({format:?}{})", path.display(), to(topic)),
            SourceSpec::Serial {
                path,
                baud,
                format,
                topic,
            } => write!(
                f,
                "serial {} {baud} baud ({format:?}{})",
                path.display(),
                to(topic)
            ),
            SourceSpec::Simulated {
                scenario,
                seed,
                speed,
                ..
            } => write!(f, "simulator {scenario} seed {seed} ×{speed}"),
            SourceSpec::Can { adapter, dbc } => write!(
                f,
                "can {adapter}{}",
                if dbc.is_some() { " (decoded)" } else { "" }
            ),
        }
    }
}

const LOCALHOST: IpAddr = IpAddr::V4(Ipv4Addr::LOCALHOST);

impl SourceSpec {
    /// Network listeners bind `ip` (127.0.0.1 until told otherwise).
    pub fn bind(mut self, ip: IpAddr) -> Self {
        if let SourceSpec::Udp { addr }
        | SourceSpec::TcpListen { addr, .. }
        | SourceSpec::Can {
            adapter: CanAdapter::Cannelloni { addr, .. },
            ..
        } = &mut self
        {
            addr.set_ip(ip);
        }
        self
    }

    /// The spec of one `record` flag (`--tcp 5601:nmea` is `kind = "tcp"`, `args = "5601:nmea"`).
    pub fn from_flag(kind: &str, args: &str) -> Result<Self, SpecError> {
        let spec = if args.is_empty() {
            kind.to_owned()
        } else {
            format!("{kind}:{args}")
        };
        spec.parse()
    }
}

impl FromStr for SourceSpec {
    type Err = SpecError;

    fn from_str(spec: &str) -> Result<Self, SpecError> {
        let (kind, args) = spec.split_once(':').unwrap_or((spec, ""));
        let port = |p: &str| {
            p.parse::<u16>()
                .map_err(|_| bad(spec, format!("'{p}' is not a port")))
        };
        Ok(match kind {
            "udp" => SourceSpec::Udp {
                addr: SocketAddr::new(LOCALHOST, port(args)?),
            },
            "tcp" => {
                let (p, fmt) = args
                    .split_once(':')
                    .map_or((args, None), |(p, f)| (p, Some(f)));
                let (format, topic) = format_or(spec, fmt, StreamFormat::JsonLines)?;
                SourceSpec::TcpListen {
                    addr: SocketAddr::new(LOCALHOST, port(p)?),
                    format,
                    topic,
                }
            }
            "tcp-client" | "tcp_client" => {
                let (addr, fmt) = split_format(args);
                if !addr.contains(':') {
                    return Err(bad(spec, "HOST:PORT[:FORMAT]"));
                }
                let (format, topic) = format_or(spec, fmt, StreamFormat::JsonLines)?;
                SourceSpec::TcpClient {
                    addr: addr.to_owned(),
                    format,
                    topic,
                }
            }
            "serial" => serial(spec, args)?,
            "file" => {
                let (path, fmt) = split_format(args);
                let (format, topic) = format_or(spec, fmt, format_by_extension(Path::new(path)))?;
                SourceSpec::File {
                    path: path.into(),
                    format,
                    topic,
                }
            }
            "stdin" => {
                let fmt = Some(args).filter(|a| !a.is_empty());
                let (format, topic) = format_or(spec, fmt, StreamFormat::JsonLines)?;
                SourceSpec::Stdin { format, topic }
            }
            "simulate" => SourceSpec::Simulated {
                scenario: if args.is_empty() {
                    "default".into()
                } else {
                    args.to_owned()
                },
                seed: 0,
                speed: 1.0,
                duration_s: None,
            },
            "can" => SourceSpec::Can {
                adapter: args.parse().map_err(|what: String| bad(spec, what))?,
                dbc: None,
            },
            other => return Err(bad(spec, format!("unknown source kind '{other}'"))),
        })
    }
}

/// A CAN adapter, as `record --can` names it:
///
/// - `IFACE` (`can0`, `vcan0`): a Linux SocketCAN interface, classic and FD frames, with the
///   kernel's receive time and its count of frames dropped on a full socket buffer;
/// - `slcan:DEVICE[:BITRATE[:TTYBAUD]]` (`slcan:/dev/ttyACM0:500000`): an SLCAN serial adapter,
///   opened at the CAN bit rate (500 kbit/s unless told; SLCAN's 10 k–1 M) and the serial
///   line at TTYBAUD (115200; a USB adapter ignores it); the bus is named after the device;
/// - `socketcand:HOST:PORT[:BUS]`: a socketcand server's bus BUS (`can0`), over TCP;
/// - `cannelloni:PORT[:BUS]`: a cannelloni gateway's datagrams on UDP PORT, named BUS
///   (`cannelloni`), with the kernel's drop count and the gateway's sequence gaps counted.
#[derive(Debug, Clone, PartialEq)]
pub enum CanAdapter {
    SocketCan {
        iface: String,
    },
    Slcan {
        path: PathBuf,
        bitrate: u32,
        baud: u32,
    },
    Socketcand {
        addr: String,
        bus: String,
    },
    Cannelloni {
        addr: SocketAddr,
        bus: String,
    },
}

impl CanAdapter {
    /// The bus's name in the log (`/can/<bus>/frames`).
    pub fn bus(&self) -> String {
        match self {
            CanAdapter::SocketCan { iface } => iface.clone(),
            CanAdapter::Slcan { path, .. } => path
                .file_name()
                .map_or_else(|| "slcan".into(), |n| n.to_string_lossy().into_owned()),
            CanAdapter::Socketcand { bus, .. } | CanAdapter::Cannelloni { bus, .. } => bus.clone(),
        }
    }
}

impl std::fmt::Display for CanAdapter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CanAdapter::SocketCan { iface } => write!(f, "socketcan {iface}"),
            CanAdapter::Slcan { path, bitrate, .. } => {
                write!(f, "slcan {} {} kbit/s", path.display(), bitrate / 1000)
            }
            CanAdapter::Socketcand { addr, bus } => write!(f, "socketcand {addr} {bus}"),
            CanAdapter::Cannelloni { addr, bus } => write!(f, "cannelloni {addr} as {bus}"),
        }
    }
}

/// A bus name: what an interface may be called (it names a channel).
fn bus_name(name: &str) -> Result<String, String> {
    let fine = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.';
    match !name.is_empty() && name.len() <= 32 && name.chars().all(fine) {
        true => Ok(name.to_owned()),
        false => Err(format!(
            "bus '{name}': up to 32 letters, digits, '_', '-' or '.' (it names a channel)"
        )),
    }
}

impl FromStr for CanAdapter {
    type Err = String;

    fn from_str(args: &str) -> Result<Self, String> {
        let parts: Vec<&str> = args.split(':').collect();
        let number = |what: &str, text: &str| {
            text.parse::<u32>()
                .map_err(|_| format!("'{text}' is not a {what}"))
        };
        let port = |text: &str| {
            text.parse::<u16>()
                .map_err(|_| format!("'{text}' is not a port"))
        };
        Ok(match parts[..] {
            [iface] => CanAdapter::SocketCan {
                iface: bus_name(iface)?,
            },
            ["slcan", path, ref rest @ ..] if rest.len() <= 2 => {
                let bitrate = match rest.first() {
                    Some(b) => number("bit rate", b)?,
                    None => 500_000,
                };
                if railfuse_can::slcan::bitrate_command(bitrate).is_none() {
                    return Err(format!(
                        "SLCAN has no code for {bitrate} bit/s: one of {}",
                        railfuse_can::slcan::BITRATES
                            .map(|b| b.to_string())
                            .join(", ")
                    ));
                }
                let baud = match rest.get(1) {
                    Some(b) => number("baud rate", b)?,
                    None => 115_200,
                };
                CanAdapter::Slcan {
                    path: path.into(),
                    bitrate,
                    baud,
                }
            }
            ["socketcand", host, p, ref rest @ ..] if rest.len() <= 1 => CanAdapter::Socketcand {
                addr: format!("{host}:{}", port(p)?),
                bus: bus_name(rest.first().unwrap_or(&"can0"))?,
            },
            ["cannelloni", p, ref rest @ ..] if rest.len() <= 1 => CanAdapter::Cannelloni {
                addr: SocketAddr::new(LOCALHOST, port(p)?),
                bus: bus_name(rest.first().unwrap_or(&"cannelloni"))?,
            },
            _ => {
                return Err("IFACE, slcan:DEVICE[:BITRATE[:TTYBAUD]], \
                            socketcand:HOST:PORT[:BUS] or cannelloni:PORT[:BUS]"
                    .into())
            }
        })
    }
}

/// `serial:DEVICE:BAUD[:FORMAT]`, NMEA unless told.
fn serial(spec: &str, args: &str) -> Result<SourceSpec, SpecError> {
    let parts: Vec<&str> = args.split(':').collect();
    let (dev, baud, fmt) = match parts[..] {
        [d, b] => (d, b, None),
        [d, b, f] => (d, b, Some(f)),
        _ => return Err(bad(spec, "DEVICE:BAUD[:FORMAT]")),
    };
    let baud = baud
        .parse()
        .map_err(|_| bad(spec, format!("'{baud}' is not a baud rate")))?;
    let (format, topic) = format_or(spec, fmt, StreamFormat::Nmea)?;
    Ok(SourceSpec::Serial {
        path: dev.into(),
        baud,
        format,
        topic,
    })
}

/// `ARGS[:FORMAT]`: the format named last, if the last part names one.
fn split_format(args: &str) -> (&str, Option<&str>) {
    match args.rsplit_once(':') {
        Some((rest, f)) if is_format(f) => (rest, Some(f)),
        _ => (args, None),
    }
}

/// A file's format from its extension: `.ubx`, `.nmea`/`.txt`, otherwise JSON lines.
fn format_by_extension(path: &Path) -> StreamFormat {
    match path.extension().and_then(|e| e.to_str()) {
        Some("ubx") => StreamFormat::Ubx,
        Some("nmea") | Some("txt") => StreamFormat::Nmea,
        _ => StreamFormat::JsonLines,
    }
}

/// `FORMAT[=TOPIC]`: the stream format and, optionally, the channel its GNSS fixes go to.
fn format_or(
    spec: &str,
    text: Option<&str>,
    default: StreamFormat,
) -> Result<(StreamFormat, Option<String>), SpecError> {
    let Some(t) = text else {
        return Ok((default, None));
    };
    let (f, topic) = match t.split_once('=') {
        Some((f, topic)) if topic.starts_with('/') => (f, Some(topic.to_owned())),
        Some((_, topic)) => {
            return Err(bad(
                spec,
                format!("the channel must start with '/', not '{topic}'"),
            ))
        }
        None => (t, None),
    };
    let format = if f.is_empty() {
        default
    } else {
        f.parse()
            .map_err(|e: crate::error::UnknownStreamFormat| bad(spec, e.to_string()))?
    };
    Ok((format, topic))
}

fn is_format(t: &str) -> bool {
    match t.split_once('=') {
        Some((f, topic)) => {
            (f.is_empty() || f.parse::<StreamFormat>().is_ok()) && topic.starts_with('/')
        }
        None => t.parse::<StreamFormat>().is_ok(),
    }
}

/// One `[[source]]` table: exactly one of the kinds, with its options.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SourceTable {
    udp: Option<u16>,
    tcp: Option<u16>,
    tcp_client: Option<String>,
    serial: Option<PathBuf>,
    baud: Option<u32>,
    file: Option<PathBuf>,
    stdin: Option<bool>,
    simulate: Option<String>,
    can: Option<String>,
    format: Option<StreamFormat>,
    topic: Option<String>,
}

impl TryFrom<SourceTable> for SourceSpec {
    type Error = SpecError;

    fn try_from(t: SourceTable) -> Result<Self, SpecError> {
        let kinds = [
            t.udp.is_some(),
            t.tcp.is_some(),
            t.tcp_client.is_some(),
            t.serial.is_some(),
            t.file.is_some(),
            t.stdin == Some(true),
            t.simulate.is_some(),
            t.can.is_some(),
        ];
        if kinds.iter().filter(|k| **k).count() != 1 {
            return Err(SpecError::Kinds);
        }
        if let Some(topic) = t.topic.as_deref().filter(|t| !t.starts_with('/')) {
            return Err(bad(
                "topic",
                format!("the channel must start with '/', not '{topic}'"),
            ));
        }
        let (format, topic) = (t.format, t.topic);
        Ok(if let Some(port) = t.udp {
            SourceSpec::Udp {
                addr: SocketAddr::new(LOCALHOST, port),
            }
        } else if let Some(port) = t.tcp {
            let format = format.unwrap_or(StreamFormat::JsonLines);
            SourceSpec::TcpListen {
                addr: SocketAddr::new(LOCALHOST, port),
                format,
                topic,
            }
        } else if let Some(addr) = t.tcp_client {
            SourceSpec::TcpClient {
                addr,
                format: format.unwrap_or(StreamFormat::JsonLines),
                topic,
            }
        } else if let Some(path) = t.serial {
            let baud = t.baud.ok_or(SpecError::NoBaud)?;
            SourceSpec::Serial {
                path,
                baud,
                format: format.unwrap_or(StreamFormat::Nmea),
                topic,
            }
        } else if let Some(path) = t.file {
            let format = format.unwrap_or_else(|| format_by_extension(&path));
            SourceSpec::File {
                path,
                format,
                topic,
            }
        } else if let Some(can) = t.can {
            SourceSpec::Can {
                adapter: can.parse().map_err(|what: String| bad(&can, what))?,
                dbc: None,
            }
        } else if let Some(scenario) = t.simulate {
            SourceSpec::Simulated {
                scenario,
                seed: 0,
                speed: 1.0,
                duration_s: None,
            }
        } else {
            SourceSpec::Stdin {
                format: format.unwrap_or(StreamFormat::JsonLines),
                topic,
            }
        })
    }
}

/// A sources file: `[[source]]` tables, and `[can] dbc = "vehicle.dbc"` (relative to the
/// file) to decode its CAN sources' frames.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourcesFile {
    pub source: Vec<SourceSpec>,
    #[serde(default)]
    pub can: Option<SourcesCan>,
}

/// `[can]` of a sources file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourcesCan {
    pub dbc: PathBuf,
}

impl SourceSpec {
    /// A CAN source that decodes with `db`; any other as it is.
    pub fn with_dbc(self, db: &std::sync::Arc<railfuse_can::dbc::Database>) -> Self {
        match self {
            SourceSpec::Can { adapter, .. } => SourceSpec::Can {
                adapter,
                dbc: Some(db.clone()),
            },
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_and_tables_give_the_same_specs_and_bad_ones_say_why() {
        let flag = SourceSpec::from_flag("serial", "/dev/ttyACM0:115200:ubx=/gnss/rx2").unwrap();
        let table: SourcesFile = toml::from_str(
            "[[source]]\nserial = \"/dev/ttyACM0\"\nbaud = 115200\nformat = \"ubx\"\ntopic = \"/gnss/rx2\"\n",
        )
        .unwrap();
        assert_eq!(table.source, vec![flag]);
        let tcp: SourceSpec = "tcp:5601:nmea".parse().unwrap();
        assert_eq!(
            tcp.bind("0.0.0.0".parse().unwrap()).to_string(),
            "tcp listen 0.0.0.0:5601 (Nmea)"
        );
        assert_eq!(
            "file:run.ubx".parse::<SourceSpec>().unwrap(),
            SourceSpec::File {
                path: "run.ubx".into(),
                format: StreamFormat::Ubx,
                topic: None
            }
        );
        assert_eq!(
            "tcp-client:rx.local:2101:nmea"
                .parse::<SourceSpec>()
                .unwrap(),
            SourceSpec::TcpClient {
                addr: "rx.local:2101".into(),
                format: StreamFormat::Nmea,
                topic: None
            }
        );
        for (spec, says) in [
            ("udp:70000", "'70000' is not a port"),
            ("serial:/dev/ttyS0", "DEVICE:BAUD[:FORMAT]"),
            ("serial:/dev/ttyS0:fast", "'fast' is not a baud rate"),
            ("tcp:5601:nmea=gnss", "must start with '/'"),
            ("tcp:5601:csv", "unknown stream format"),
            ("carrier-pigeon:1", "unknown source kind"),
            ("can:slcan:/dev/ttyACM0:300000", "no code for 300000"),
            ("can:socketcand:host:x", "'x' is not a port"),
            ("can:can0/../x", "up to 32 letters"),
            ("can:a:b:c:d:e", "IFACE, slcan"),
        ] {
            let e = spec.parse::<SourceSpec>().unwrap_err().to_string();
            assert!(e.starts_with(spec) && e.contains(says), "{spec}: {e}");
        }
        let slcan: SourceSpec = "can:slcan:/dev/ttyACM0:1000000".parse().unwrap();
        assert_eq!(slcan.to_string(), "can slcan /dev/ttyACM0 1000 kbit/s");
        let table: SourcesFile =
            toml::from_str("[[source]]\ncan = \"slcan:/dev/ttyACM0:1000000\"\n").unwrap();
        assert_eq!(table.source, vec![slcan]);
        let remote: SourceSpec = "can:socketcand:gw.local:29536".parse().unwrap();
        assert_eq!(remote.to_string(), "can socketcand gw.local:29536 can0");
        let two = toml::from_str::<SourcesFile>("[[source]]\nudp = 1\ntcp = 2\n");
        assert!(two.unwrap_err().to_string().contains("exactly one of"));
        let no_baud = toml::from_str::<SourcesFile>("[[source]]\nserial = \"/dev/ttyS0\"\n");
        assert!(no_baud
            .unwrap_err()
            .to_string()
            .contains("serial needs baud"));
    }
}

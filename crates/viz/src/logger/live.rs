//! [`LiveViz`]: the viewer fed message by message while recording or re-fusing, and the check
//! that a viewer listens before anything is streamed to it.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use railfuse_catalog::log::{ChannelInfo, LogMessage, SchemaInfo};

use super::{open_stream, Logger, Sink, VizOptions, VizReport, LIVE_FLUSH, VIEWER_TIMEOUT};
use crate::series::Decimation;
use crate::Error;

/// Streams messages to Rerun as they are recorded or re-fused (`record --viz`,
/// `refuse --viz`): the layout of `railfuse viz`, fed one message at a time.
///
/// Dropping it finishes it (what is buffered goes out, waiting for the viewer at most 30 s).
pub struct LiveViz {
    logger: Logger,
    channels: HashMap<(String, String), Arc<ChannelInfo>>,
    last_flush: Instant,
    finished: bool,
}

impl LiveViz {
    pub fn open(sink: &Sink, options: &VizOptions) -> Result<Self, Error> {
        let mut logger = Logger::new(
            open_stream(sink)?,
            PathBuf::from("<live>"),
            options.clone(),
            Decimation::Full,
            0,
        );
        logger.send_blueprint()?;
        Ok(Self {
            logger,
            channels: Default::default(),
            last_flush: Instant::now(),
            finished: false,
        })
    }

    /// Logs one message given as its topic, schema name, log time and JSON payload.
    pub fn message(
        &mut self,
        topic: &str,
        schema: &str,
        log_time_ns: u64,
        json: &[u8],
    ) -> Result<(), Error> {
        let n = self.channels.len() as u16;
        let channel = self
            .channels
            .entry((topic.to_owned(), schema.to_owned()))
            .or_insert_with(|| {
                Arc::new(ChannelInfo {
                    id: n,
                    topic: topic.to_owned(),
                    message_encoding: "json".into(),
                    metadata: Default::default(),
                    schema: Some(Arc::new(SchemaInfo {
                        id: n,
                        name: schema.to_owned(),
                        encoding: "jsonschema".into(),
                        data: Vec::new(),
                    })),
                })
            });
        let m = LogMessage {
            channel,
            sequence: 0,
            log_time_ns,
            publish_time_ns: log_time_ns,
            data: json,
        };
        self.logger.start_ns.get_or_insert(log_time_ns);
        self.logger.report.messages += 1;
        self.logger.message(&m)?;
        if self.last_flush.elapsed() >= LIVE_FLUSH {
            self.last_flush = Instant::now();
            self.logger.columns.flush(&self.logger.rec)?;
            self.logger.send_blueprint_if_changed()?;
        }
        Ok(())
    }

    /// Sends what is buffered and the final layout, and waits (bounded) for the viewer.
    pub fn finish(&mut self) -> Result<VizReport, Error> {
        if std::mem::replace(&mut self.finished, true) {
            return Ok(self.logger.report());
        }
        self.logger.finish()?;
        self.logger
            .rec
            .flush_with_timeout(VIEWER_TIMEOUT)
            .map_err(|e| Error::Rerun(e.to_string()))?;
        Ok(self.logger.report())
    }
}

impl Drop for LiveViz {
    fn drop(&mut self) {
        // Nowhere to report to: a viewer that went away was reported when it did.
        let _ = self.finish();
    }
}

/// Checks that something listens at the viewer URL's host and port before streaming: the SDK
/// would otherwise queue data and retry for ever against an address where no viewer runs.
pub(super) fn probe_viewer(url: &str) -> Result<(), Error> {
    use std::net::{TcpStream, ToSocketAddrs};
    let authority = url
        .split("://")
        .nth(1)
        .and_then(|rest| rest.split('/').next())
        .filter(|a| a.contains(':'));
    let Some(authority) = authority else {
        return Err(Error::Rerun(format!(
            "{url}: expected a viewer URL like rerun+http://127.0.0.1:9876/proxy"
        )));
    };
    let addrs = authority
        .to_socket_addrs()
        .map_err(|e| Error::Rerun(format!("{url}: {e}")))?;
    for addr in addrs {
        if TcpStream::connect_timeout(&addr, Duration::from_secs(3)).is_ok() {
            return Ok(());
        }
    }
    Err(Error::Rerun(format!(
        "{url}: no Rerun viewer is listening there (start one with `rerun`)"
    )))
}

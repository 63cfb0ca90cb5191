//! Reading a MILV recording back (tests, round-trip checks, scripts): every message with
//! its topic and schema, the metadata records and the attachments, chunk CRCs checked.

use std::collections::BTreeMap;
use std::path::Path;

use mcap::read::Options;
use prost::Message;
use serde_json::Value;

use crate::schema::Tensor;
use crate::{Error, Result};

/// One message as read.
#[derive(Clone, Debug)]
pub struct RecordedMessage {
    pub topic: String,
    /// Schema name, e.g. `foxglove.CompressedImage`.
    pub schema: String,
    pub log_time: u64,
    pub data: Vec<u8>,
}

impl RecordedMessage {
    pub fn tensor(&self) -> Result<Tensor> {
        Tensor::decode(self.data.as_slice())
            .map_err(|e| Error::Invalid(format!("{}: not a milv.Tensor: {e}", self.topic)))
    }

    pub fn image(&self) -> Result<foxglove::messages::CompressedImage> {
        foxglove::messages::CompressedImage::decode(self.data.as_slice())
            .map_err(|e| Error::Invalid(format!("{}: not a foxglove.CompressedImage: {e}", self.topic)))
    }

    pub fn json(&self) -> Result<Value> {
        Ok(serde_json::from_slice(&self.data)?)
    }
}

/// A whole MCAP file.
#[derive(Clone, Debug, Default)]
pub struct Recording {
    pub messages: Vec<RecordedMessage>,
    /// Metadata records in file order: (name, key → value).
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// Attachments: (name, media type, bytes).
    pub attachments: Vec<(String, String, Vec<u8>)>,
    /// Message count per topic from the file's statistics record.
    pub stats: BTreeMap<String, u64>,
}

impl Recording {
    pub fn read(path: &Path) -> Result<Recording> {
        let buf = std::fs::read(path).map_err(|source| Error::Io {
            op: "read",
            source,
            path: path.to_path_buf(),
        })?;
        let e = |source| Error::Mcap {
            source,
            path: path.to_path_buf(),
        };
        let mut rec = Recording::default();
        for m in mcap::MessageStream::new_with_options(&buf, Options::ValidateChunkCrcs.into()).map_err(e)? {
            let m = m.map_err(e)?;
            rec.messages.push(RecordedMessage {
                topic: m.channel.topic.clone(),
                schema: m
                    .channel
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default(),
                log_time: m.log_time,
                data: m.data.into_owned(),
            });
        }
        let summary = mcap::Summary::read(&buf)
            .map_err(e)?
            .ok_or_else(|| Error::Invalid(format!("no summary section: {}", path.display())))?;
        for idx in &summary.metadata_indexes {
            let m = mcap::read::metadata(&buf, idx).map_err(e)?;
            rec.metadata.push((m.name, m.metadata));
        }
        for idx in &summary.attachment_indexes {
            let a = mcap::read::attachment(&buf, idx).map_err(e)?;
            rec.attachments.push((a.name, a.media_type, a.data.into_owned()));
        }
        if let Some(stats) = &summary.stats {
            for c in summary.channels.values() {
                let n = stats.channel_message_counts.get(&c.id).copied().unwrap_or(0);
                rec.stats.insert(c.topic.clone(), n);
            }
        }
        Ok(rec)
    }

    /// The messages of one topic, in log-time order.
    pub fn topic<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a RecordedMessage> + 'a {
        self.messages.iter().filter(move |m| m.topic == topic)
    }

    /// The first metadata record of this name.
    pub fn metadata(&self, name: &str) -> Option<&BTreeMap<String, String>> {
        self.metadata.iter().find(|(n, _)| n == name).map(|(_, m)| m)
    }
}

//! Messages a run could not read, counted by topic and cause, each cause with its first
//! occurrence in words: what `refuse` and `viz` say about bad input, one line per cause (a
//! payload cut short and a NaN latitude on the same topic are two lines, a thousand cut
//! payloads one).

use std::collections::BTreeMap;

/// The most causes kept apart; later new ones are counted under the total only, so a hostile
/// file cannot grow the report without bound.
pub const MAX_CAUSES: usize = 32;

/// One cause of rejection on one topic.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Cause {
    pub topic: String,
    pub count: u64,
    /// The first message rejected for it, in words (topic, log time and why).
    pub first: String,
}

#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rejections {
    /// Every message rejected, whatever its cause.
    pub total: u64,
    /// By `topic` and kind of cause.
    pub causes: BTreeMap<String, Cause>,
}

impl Rejections {
    /// Counts one message of `topic` rejected for a cause of `kind`; `first` (called only
    /// for a cause's first message) says it.
    pub fn add(&mut self, topic: &str, kind: &str, first: impl FnOnce() -> String) {
        self.total += 1;
        let key = format!("{topic} {kind}");
        if let Some(c) = self.causes.get_mut(&key) {
            c.count += 1;
        } else if self.causes.len() < MAX_CAUSES {
            let cause = Cause {
                topic: topic.to_owned(),
                count: 1,
                first: first(),
            };
            self.causes.insert(key, cause);
        }
    }

    /// One line per cause: how many messages, and the first.
    pub fn lines(&self) -> Vec<String> {
        let mut lines: Vec<String> = self
            .causes
            .values()
            .map(|c| {
                format!(
                    "{} sensor messages did not decode and were skipped; the first: {}",
                    c.count, c.first
                )
            })
            .collect();
        let kept: u64 = self.causes.values().map(|c| c.count).sum();
        if kept < self.total {
            lines.push(format!(
                "{} more messages did not decode, for causes past the first {MAX_CAUSES}",
                self.total - kept
            ));
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_are_kept_apart_by_topic_and_kind_and_bounded() {
        let mut r = Rejections::default();
        for k in 0..3 {
            r.add("/fix", "cdr", || format!("/fix: log time {k}: cut short"));
        }
        r.add("/fix", "invalid", || "/fix: NaN latitude".into());
        r.add("/radar", "cdr", || "/radar: cut short".into());
        assert_eq!(r.total, 5);
        let lines = r.lines();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!(
            lines[0].starts_with("3 sensor messages")
                && lines[0].ends_with("log time 0: cut short")
        );
        for k in 0..100 {
            r.add(&format!("/t{k}"), "cdr", || "x".into());
        }
        assert_eq!(r.causes.len(), MAX_CAUSES);
        assert_eq!(r.total, 105);
        assert!(r.lines().last().unwrap().contains("past the first 32"));
    }
}

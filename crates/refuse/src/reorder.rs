//! The reorder window: sensors with different latencies reach the log out of sensor-time
//! order, and a filter must see them in it. Items wait here until the replay is a window past
//! their stamp, then leave in (stamp, arrival) order: equal stamps keep the order they came in.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

/// Items waiting to be released in stamp order.
#[derive(Debug)]
pub struct ReorderQueue<T> {
    heap: BinaryHeap<Reverse<Entry<T>>>,
    arrivals: u64,
}

#[derive(Debug)]
struct Entry<T> {
    stamp_ns: u64,
    arrival: u64,
    item: T,
}

impl<T> PartialEq for Entry<T> {
    fn eq(&self, other: &Self) -> bool {
        (self.stamp_ns, self.arrival) == (other.stamp_ns, other.arrival)
    }
}
impl<T> Eq for Entry<T> {}
impl<T> PartialOrd for Entry<T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl<T> Ord for Entry<T> {
    fn cmp(&self, other: &Self) -> Ordering {
        (self.stamp_ns, self.arrival).cmp(&(other.stamp_ns, other.arrival))
    }
}

impl<T> Default for ReorderQueue<T> {
    fn default() -> Self {
        Self {
            heap: BinaryHeap::new(),
            arrivals: 0,
        }
    }
}

impl<T> ReorderQueue<T> {
    pub fn push(&mut self, stamp_ns: u64, item: T) {
        self.arrivals += 1;
        self.heap.push(Reverse(Entry {
            stamp_ns,
            arrival: self.arrivals,
            item,
        }));
    }

    /// The earliest item stamped at or before `up_to_ns`, if any.
    pub fn pop_until(&mut self, up_to_ns: u64) -> Option<(u64, T)> {
        if self.heap.peek()?.0.stamp_ns > up_to_ns {
            return None;
        }
        self.heap.pop().map(|Reverse(e)| (e.stamp_ns, e.item))
    }

    pub fn len(&self) -> usize {
        self.heap.len()
    }

    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn items_leave_in_stamp_order_and_equal_stamps_in_arrival_order() {
        let mut q = ReorderQueue::default();
        q.push(30, 'c');
        q.push(10, 'a');
        q.push(30, 'd');
        q.push(20, 'b');
        assert_eq!(q.pop_until(15), Some((10, 'a')));
        assert_eq!(q.pop_until(15), None);
        let rest: Vec<char> =
            std::iter::from_fn(|| q.pop_until(u64::MAX).map(|(_, c)| c)).collect();
        assert_eq!(rest, ['b', 'c', 'd']);
        assert!(q.is_empty());
    }
}

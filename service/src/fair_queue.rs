//! Which waiting request the serving thread answers next: one request per client per round.
//!
//! iceoryx2's `Server::receive` scans its client connections in a fixed order and returns the
//! first request it finds, so a client that always keeps a request queued (a flooder with four
//! in flight) is answered before every client behind it in that order, for as long as it keeps
//! sending: the clients behind it wait until its budget runs out, hundreds of milliseconds.
//!
//! The serving loop therefore takes every request that is waiting into a [`FairQueue`] and
//! answers them in rounds: within a round each client is answered at most once, in the order
//! its requests arrived; a client whose request was answered this round waits for the next. A
//! well-behaved client's request waits for at most one request of every other client (one full
//! batch of a flooder, about half a millisecond), never for a client's whole backlog.
//!
//! Fixed capacity, reserved at construction: nothing is allocated while serving.

/// Requests waiting to be answered, with the client each came from.
#[derive(Debug)]
pub struct FairQueue<R> {
    /// Waiting requests in arrival order: `(client id, request)`.
    waiting: Vec<(u128, R)>,
    /// Clients answered in the current round.
    answered: Vec<u128>,
}

impl<R> FairQueue<R> {
    /// A queue holding at most `capacity` requests from up to `clients` clients per round.
    pub fn with_capacity(capacity: usize, clients: usize) -> Self {
        Self {
            waiting: Vec::with_capacity(capacity),
            answered: Vec::with_capacity(clients),
        }
    }

    /// Whether another request fits without allocating.
    pub fn has_room(&self) -> bool {
        self.waiting.len() < self.waiting.capacity()
    }

    /// Whether no request waits.
    pub fn is_empty(&self) -> bool {
        self.waiting.is_empty()
    }

    /// Adds a request of `client` behind those already waiting. The caller checks
    /// [`has_room`](Self::has_room) first; beyond the capacity the queue would allocate.
    pub fn push(&mut self, client: u128, request: R) {
        debug_assert!(self.has_room(), "FairQueue pushed beyond its capacity");
        self.waiting.push((client, request));
    }

    /// The next request to answer and its client: the earliest-arrived request of a client not
    /// yet answered this round; when every waiting client has been, a new round starts.
    pub fn pop(&mut self) -> Option<(u128, R)> {
        if self.waiting.is_empty() {
            return None;
        }
        let next = match self
            .waiting
            .iter()
            .position(|(client, _)| !self.answered.contains(client))
        {
            Some(index) => index,
            // Every waiting client was answered this round: the next round starts.
            None => {
                self.answered.clear();
                0
            }
        };
        let (client, request) = self.waiting.remove(next);
        if self.answered.len() == self.answered.capacity() {
            self.answered.clear();
        }
        self.answered.push(client);
        Some((client, request))
    }

    /// Takes the earliest-arrived request for which `eligible(client, request)` holds, outside
    /// the rounds: the current round is neither advanced nor reset (used between the steps of
    /// a large batch, whose own round goes on after it).
    pub fn take_first(&mut self, mut eligible: impl FnMut(u128, &R) -> bool) -> Option<(u128, R)> {
        let index = self
            .waiting
            .iter()
            .position(|(client, request)| eligible(*client, request))?;
        Some(self.waiting.remove(index))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drain(queue: &mut FairQueue<&'static str>) -> Vec<&'static str> {
        std::iter::from_fn(|| queue.pop().map(|(_, r)| r)).collect()
    }

    #[test]
    fn a_backlog_does_not_go_ahead_of_other_clients() {
        let mut queue = FairQueue::with_capacity(16, 4);
        // The flooder's four requests arrived first, then one of each paced client.
        for r in ["f1", "f2", "f3", "f4"] {
            queue.push(1, r);
        }
        queue.push(2, "a1");
        queue.push(3, "b1");
        assert_eq!(drain(&mut queue), ["f1", "a1", "b1", "f2", "f3", "f4"]);
    }

    #[test]
    fn a_request_arriving_mid_round_waits_only_for_clients_not_yet_answered() {
        let mut queue = FairQueue::with_capacity(16, 4);
        queue.push(1, "f1");
        queue.push(1, "f2");
        queue.push(2, "a1");
        assert_eq!(queue.pop().unwrap().1, "f1");
        // Client 3 arrives after the flooder's first answer: it goes before the flooder's
        // second request, after client 2 (which arrived earlier).
        queue.push(3, "b1");
        assert_eq!(drain(&mut queue), ["a1", "b1", "f2"]);
    }

    #[test]
    fn a_lone_client_is_answered_in_order() {
        let mut queue = FairQueue::with_capacity(8, 2);
        for r in ["1", "2", "3"] {
            queue.push(9, r);
        }
        assert_eq!(drain(&mut queue), ["1", "2", "3"]);
        assert!(queue.is_empty());
        assert!(queue.pop().is_none());
    }

    #[test]
    fn more_clients_than_a_round_holds_start_a_new_round_without_allocating() {
        let mut queue = FairQueue::with_capacity(8, 2);
        for client in 0..6u128 {
            queue.push(client, "r");
        }
        let capacity = (queue.waiting.capacity(), queue.answered.capacity());
        let clients: Vec<_> = std::iter::from_fn(|| queue.pop().map(|(c, _)| c)).collect();
        assert_eq!(clients, [0, 1, 2, 3, 4, 5]);
        assert_eq!(
            (queue.waiting.capacity(), queue.answered.capacity()),
            capacity
        );
    }

    #[test]
    fn taking_outside_the_rounds_takes_the_earliest_eligible_one() {
        let mut queue = FairQueue::with_capacity(8, 4);
        queue.push(1, "big");
        queue.push(2, "s1");
        queue.push(3, "t1");
        queue.push(2, "s2");
        let small = |_: u128, r: &&str| !r.starts_with('b');
        assert_eq!(queue.take_first(small).unwrap(), (2, "s1"));
        assert_eq!(
            queue.take_first(|c, r| c != 3 && small(c, r)).unwrap(),
            (2, "s2")
        );
        assert_eq!(queue.take_first(small).unwrap(), (3, "t1"));
        assert!(queue.take_first(small).is_none());
        assert_eq!(queue.pop().unwrap(), (1, "big"));
    }

    #[test]
    fn taking_outside_the_rounds_does_not_reset_the_round() {
        let mut queue = FairQueue::with_capacity(16, 4);
        // A small client answered first, then a flooder's backlog and a batch client behind it.
        queue.push(9, "s0");
        for r in ["f1", "f2", "f3"] {
            queue.push(1, r);
        }
        queue.push(2, "b1");
        assert_eq!(queue.pop().unwrap().1, "s0");
        assert_eq!(queue.pop().unwrap().1, "f1");
        // During the flooder's batch the small client (answered this round) sends again and is
        // taken between two steps; the flooder's next request must still wait for the batch
        // client.
        queue.push(9, "s1");
        assert_eq!(queue.take_first(|c, _| c == 9).unwrap().1, "s1");
        assert_eq!(drain(&mut queue), ["b1", "f2", "f3"]);
    }

    #[test]
    fn room_is_the_capacity() {
        let mut queue = FairQueue::with_capacity(2, 2);
        queue.push(1, "a");
        assert!(queue.has_room());
        queue.push(2, "b");
        assert!(!queue.has_room());
    }
}

//! Answering the compensation requests that wait, fairly: every waiting request is taken into a
//! [`FairQueue`] (one request per client per round), each is admitted against its client's
//! budget ([`Admission`]), and a large batch steps aside every [`STEP_POINTS`] points for the
//! small requests that arrived meanwhile, so that an NC client's single point never waits for a
//! whole 1024-point batch of another client (about 0.5 ms) but for at most one step of it.
//!
//! Answers are written from the loaned request straight into the loaned response; nothing is
//! allocated here (the queue's capacity is reserved once).

use std::sync::atomic::Ordering;

use hexacomp_core::Geometry;
use hexacomp_protocol::{
    MAX_BATCH, MAX_CLIENTS, MAX_REQUESTS_IN_FLIGHT, PROTOCOL_VERSION, PointRequest, PointResponse,
    RequestHeader, RequestKind, RequestOutcome, ResponseHeader,
};
use iceoryx2::port::ReceiveError;
use iceoryx2::prelude::*;

use crate::admission::Admission;
use crate::fair_queue::FairQueue;
use crate::serving::{CompensationServer, check_header, compute_pair, compute_point};
use crate::{Counters, Generation};

/// Points of a large batch computed between two looks for small requests (about 30 µs of
/// compute on the development machines); requests of at most this many points are the small
/// ones that a large batch steps aside for.
pub const STEP_POINTS: usize = 64;
// Points are computed in pairs from even indices: a step boundary must fall between two pairs.
const _: () = assert!(STEP_POINTS.is_multiple_of(2));

type ActiveRequest = iceoryx2::active_request::ActiveRequest<
    ipc::Service,
    [PointRequest],
    RequestHeader,
    [PointResponse],
    ResponseHeader,
>;

/// The serving thread's answering state: its server port, the requests taken from it and not
/// yet answered, and the clients' budgets.
pub struct Answerer<'a> {
    server: &'a CompensationServer,
    geometry: &'a Geometry,
    counters: &'a Counters,
    /// Each with the time it was taken from the server port.
    waiting: FairQueue<(std::time::Instant, ActiveRequest)>,
    admission: Admission,
}

impl<'a> Answerer<'a> {
    /// Answers requests from `server` for `geometry`, each client within `client_budget`
    /// points per second (`None`: unlimited), counting in `counters`.
    pub fn new(
        server: &'a CompensationServer,
        geometry: &'a Geometry,
        counters: &'a Counters,
        client_budget: Option<f64>,
    ) -> Self {
        Self {
            server,
            geometry,
            counters,
            waiting: FairQueue::with_capacity(MAX_CLIENTS * MAX_REQUESTS_IN_FLIGHT, MAX_CLIENTS),
            admission: Admission::new(client_budget),
        }
    }

    /// Takes the requests that wait and answers the next one with `model`. Returns false when
    /// no request was waiting.
    pub fn answer_next(&mut self, model: Option<&Generation>) -> bool {
        self.receive_waiting();
        match self.waiting.pop() {
            Some((client, (taken, active))) => {
                self.answer(taken, &active, client, model);
                true
            }
            None => false,
        }
    }

    /// Takes every request that waits into the queue, as far as it has room (see
    /// [`crate::fair_queue`] for why all of them, not the first one found).
    fn receive_waiting(&mut self) {
        while self.waiting.has_room() {
            match self.server.receive() {
                Ok(Some(active)) => {
                    let taken = std::time::Instant::now();
                    self.waiting.push(active.origin().value(), (taken, active));
                }
                Ok(None) => break,
                // Every client with a request queued already has its in-flight limit held here
                // (a client that gave up on a request may send another before it is answered).
                Err(ReceiveError::ExceedsMaxBorrows) => break,
                Err(e) => {
                    tracing::warn!("receiving a request failed: {e:?}");
                    self.counters.errors.fetch_add(1, Ordering::Relaxed);
                    break;
                }
            }
        }
    }

    /// Between two steps of a large batch: answers the small requests that wait, at most one
    /// per client, in the order they arrived, outside the rounds (the batch's round goes on).
    fn answer_small_waiting(&mut self, model: Option<&Generation>) {
        self.receive_waiting();
        let mut answered = [0u128; MAX_CLIENTS];
        let mut count = 0;
        while let Some((client, (taken, active))) =
            self.waiting.take_first(|client, (_, active)| {
                active.payload().len() <= STEP_POINTS && !answered[..count].contains(&client)
            })
        {
            if count < MAX_CLIENTS {
                answered[count] = client;
                count += 1;
            }
            self.answer(taken, &active, client, model);
        }
    }

    /// Answers one request of `client` from its loaned payload straight into a loaned
    /// response. A client that stopped waiting (its deadline passed) gets no answer, as
    /// iceoryx2's receive skips such requests: computing one would only delay the others.
    /// The time from `taken` to the answer's send is counted in the answer times.
    fn answer(
        &mut self,
        taken: std::time::Instant,
        active: &ActiveRequest,
        client: u128,
        model: Option<&Generation>,
    ) {
        if !active.is_connected() {
            return;
        }
        let header = *active.user_header();
        let points = active.payload();
        let count = points.len();
        let (outcome, kind) = match self.triage(&header, count, client, taken) {
            Ok(kind) => (RequestOutcome::Served, Some(kind)),
            Err(outcome) => (outcome, None),
        };
        let geometry = self.geometry;
        // The second point of a pair, computed with the first: its index and its answer.
        let mut computed_ahead: Option<(usize, PointResponse)> = None;
        let sent = match active.loan_slice_uninit(if kind.is_some() { count } else { 0 }) {
            // `write_from_fn` fills the points in index order, two at a time where it can (the
            // second kept until its index comes); every STEP_POINTS of them (an even number),
            // the small requests that arrived meanwhile are answered first.
            Ok(loan) => {
                let mut response = loan.write_from_fn(|i| match kind {
                    Some(kind) => {
                        // `write_from_fn` visits the indices in order; the index is checked all the
                        // same, so that another order could only cost a computation.
                        if let Some((_, point)) = computed_ahead.take().filter(|(at, _)| *at == i) {
                            return point;
                        }
                        if i > 0 && i % STEP_POINTS == 0 {
                            self.answer_small_waiting(model);
                        }
                        match points.get(i + 1) {
                            Some(next) => {
                                let [point, next] =
                                    compute_pair(geometry, model, kind, [&points[i], next]);
                                computed_ahead = Some((i + 1, next));
                                point
                            }
                            None => compute_point(geometry, model, kind, &points[i]),
                        }
                    }
                    None => PointResponse::default(),
                });
                *response.user_header_mut() = ResponseHeader {
                    protocol: PROTOCOL_VERSION,
                    outcome: outcome as u32,
                    generation: model.map_or(0, |g| g.number),
                };
                response.send().is_ok()
            }
            Err(_) => false,
        };
        // The answer times are the NC's kind of request: served, of at most STEP_POINTS points.
        // Batches take as long as their points (a 1024-point batch about 0.3 ms) and refusals
        // none; they are counted apart (requests, overloaded, errors).
        if sent && outcome == RequestOutcome::Served && count <= STEP_POINTS {
            self.counters.answer_times.record(taken.elapsed());
        }
        let counter = match (sent, outcome) {
            (true, RequestOutcome::Served) => {
                self.counters
                    .points
                    .fetch_add(count as u64, Ordering::Relaxed);
                &self.counters.requests
            }
            (true, RequestOutcome::Overloaded) => &self.counters.overloaded,
            _ => &self.counters.errors,
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// What to do with a request: compute its points, or answer at once with an outcome and
    /// none.
    /// The client's budget is charged as of `taken`, when the request was taken (one clock
    /// read per request serves both the budget and the answer times).
    fn triage(
        &mut self,
        header: &RequestHeader,
        count: usize,
        client: u128,
        taken: std::time::Instant,
    ) -> Result<RequestKind, RequestOutcome> {
        let kind = check_header(header)?;
        if count > MAX_BATCH {
            return Err(RequestOutcome::BatchTooLarge);
        }
        let (waiting, server) = (&self.waiting, self.server);
        let others_waiting = || !waiting.is_empty() || server.has_requests().unwrap_or(false);
        if !self
            .admission
            .admit(client, count, || taken, others_waiting)
        {
            return Err(RequestOutcome::Overloaded);
        }
        Ok(kind)
    }
}

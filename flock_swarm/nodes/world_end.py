"""The world's outputs and its end: the bag and the time series opened, the run ended once.

:class:`WorldEnd` is the part of the world node (:mod:`flock_swarm.nodes.world`) that opens
its outputs (the bag, :class:`~flock_swarm.nodes.recording.BagSink`; the spooled time
series; the scenario and the obstacle map published and recorded at t = 0) and ends the
run: ``completed``, ``failed`` with the line telling why,
``recording_failed``, ``interrupted`` by a stop signal, or ``refused`` beside another world.
It announces the end on ``swarm/status``, records it in the bag (the ``flock_swarm_end``
metadata record ``analyze`` reads), writes ``summary.json`` and ``timeseries.npz``, closes
the sinks and logs the end line.
"""

import shutil
import time
from pathlib import Path

from rclpy.duration import Duration
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from flock_swarm.bag.writer import serialize
from flock_swarm.contract import FRAME, OBSTACLES, OBSTACLES_QOS, SCENARIO, SCENARIO_QOS, \
    qos_profile
from flock_swarm.core.errors import ScenarioError
from flock_swarm.core.headline import result_line
from flock_swarm.core.summary import with_failure
from flock_swarm.nodes.markers import obstacle_markers
from flock_swarm.nodes.recording import BagSink, provenance, provenance_text
from flock_swarm.outputs import (SpooledRecorder, json_text, write_error, write_outputs,
                                 write_text)


class WorldEnd:
    """The world node's outputs and end (a part of :class:`~flock_swarm.nodes.world.WorldNode`:
    it reads the node's ``stepper``, ``scenario``, ``params``, ``sinks``, ``timer``)."""

    def open_outputs(self, out_dir: str) -> None:
        """Choose the output directory, open the spooled time series and the bag.

        :param out_dir: the ``out_dir`` parameter (empty: ``out/<scenario>_ros``).
        :raises ScenarioError: naming ``out_dir`` when it cannot be written, or ``record``.
        """
        params, sc = self.params, self.scenario
        self.out = Path(out_dir) if out_dir else Path('out') / f'{sc.name}_ros'
        params.declare(out_dir=str(self.out))
        # The time series goes to disk as it is recorded: memory stays flat on long runs.
        self.spool = SpooledRecorder(self.out, self.get_logger().warning)
        #: The files of the run's outputs written, and why writing one failed (or ``None``).
        self.written: list[Path] = []
        self.write_error: str | None = None
        self.bag = None

    def open_bag(self) -> None:
        """Open the bag (``record``) and the spool; the bag becomes the first sink."""
        params = self.params
        self.bag = BagSink(self.out / 'bag', self.scenario, self.stepper.real, self.mode,
                           self.recording_failed, max_bagfile_size=params['bag_max_size'],
                           max_bagfile_duration=params['bag_max_duration']) \
            if params['record'] else None
        try:
            self.spool.open()
        except OSError as exc:
            raise ScenarioError('out_dir', f'cannot write to {self.out}: {exc.strerror}') \
                from None
        self.sinks = [] if self.bag is None else [self.bag]

    def publish_provenance(self) -> None:
        """Publish and record the scenario and the obstacle map at t = 0 (latched), then
        write them to the sinks."""
        sc = self.scenario
        # Latched, and recorded at t = 0: the bag keeps the scenario where tools that drop
        # MCAP metadata (rosbags-convert) keep it too (analyze reads it there).
        self.scenario_pub = self.recorded_publisher(String, SCENARIO, qos_profile(SCENARIO_QOS))
        self.publish_recorded(self.scenario_pub, String(data=provenance_text(
            provenance(sc, self.stepper.real, self.mode))), 0)
        #: The obstacle map's bytes as published (None without obstacles): a live view
        #: served after the start sends them to its viewers (InProcessSwarm.serve).
        self.obstacles_map: bytes | None = None
        if sc.obstacles.active:
            # The map for viewers, latched and recorded at t = 0 (docs/obstacles.md).
            self.obstacles_pub = self.recorded_publisher(MarkerArray, OBSTACLES,
                                                         qos_profile(OBSTACLES_QOS))
            self.obstacles_map = serialize(obstacle_markers(
                sc.obstacles, sc.dim, self.clock.stamp(0), FRAME))
            self.publish_recorded(self.obstacles_pub, self.obstacles_map, 0)
        for sink in self.sinks:
            sink.flush()

    def finish(self, status: str, failure: str | None = None) -> None:
        """Write ``summary.json`` and ``timeseries.npz``, close the bag; idempotent.

        :param status: how the run ended.
        :param failure: the line telling why it failed (``failed``, ``recording_failed``).
        """
        if self.stepper.end(status, failure):
            self.timer.cancel()
            self.write_results()

    def fail(self, line: str | None) -> None:
        """End the run as ``failed`` with ``line`` (one error line in the log); nothing
        when ``line`` is ``None`` or the run has ended."""
        if line is None or self.done:
            return
        self.get_logger().error(f'run failed: {line}')
        self.finish('failed', line)

    def recording_failed(self, reason: str) -> None:
        """Stop the run cleanly when the bag cannot be written (status ``recording_failed``).

        The bag keeps every chunk written before (see :class:`BagSink`).
        """
        self.get_logger().error(f'recording failed: {reason}; stopping the run, the bag '
                                'keeps every chunk written before')
        self.finish('recording_failed', f'recording failed: {reason}')

    def write_results(self) -> None:
        """Announce the end on ``swarm/status``; write what was recorded so far (also on an
        interrupted run), close the sinks."""
        # Commands that came but were still queued are judged, counted and recorded too.
        self.intake.take()
        self.status_pub.publish(String(data=self.stepper.status))
        recorded = self.bag is not None
        if recorded and self.bag.empty:
            # Stopped before the first step (a signal in the start wait): no empty bag.
            self.bag.discard()
            self.sinks.remove(self.bag)
            recorded = False
            self.get_logger().warning(
                f'the run ended ({self.stepper.status}) before its first step: nothing was '
                f'recorded, no bag written; {self.out / "summary.json"} says so')
        st = self.stepper
        if recorded:
            # The run's end in the bag, for analyze (its status and failure line).
            self.bag.record_end(st.status, st.failure, st.k)
        result = self.stepper.result(time.monotonic(), self.guard.counts(),
                                     sorted(self.duplicates), self.bag_error,
                                     str(self.out / 'bag') if recorded else None)
        for sink in self.sinks:
            try:
                sink.close()
            except OSError as exc:
                self.get_logger().error(f'cannot finalise {sink}: {exc.strerror or exc}; its '
                                        'complete chunks stay readable')
        self.result = result
        try:
            self.written = write_outputs(result, self.out, self.scenario)
        except OSError as exc:
            self.outputs_failed(exc)
        else:
            self.spool.discard()
        if self.progress is None:
            self.log_end(recorded)

    def log_end(self, recorded: bool) -> None:
        """Log how the run ended and the files written, as ``swarm`` prints them: a world
        logging its progress (``ros2 run``, ``swarm --processes``) ends its log with them,
        after a stop signal too."""
        log = self.get_logger()
        summary = self.result.summary
        line = result_line(summary, self.scenario.headline, ('collisions', 'missed_commands'))
        (log.info if summary.get('status') == 'completed' else log.warning)(line)
        paths = ([self.out / 'bag'] if recorded else []) + [
            path for path in self.written if path.name != 'scenario.json']
        log.info('wrote ' + ', '.join(str(path) for path in paths))

    def outputs_failed(self, exc: OSError) -> None:
        """A file of the outputs could not be written: log one line naming it, keep the
        spooled time series, and still write ``summary.json`` if it was not the one that
        failed, with status ``recording_failed`` and the line (``failure``; a run that had
        failed already keeps its own)."""
        self.spool.close()
        line = write_error(exc)
        self.write_error = line
        self.get_logger().error(f'{line}; the time series stays in {self.spool.spool}')
        self.written = [path for path in (self.out / 'timeseries.npz',
                                          self.out / 'scenario.json')
                        if path.is_file() and str(path) != exc.filename]
        summary = self.out / 'summary.json'
        if str(summary) == exc.filename:
            return
        before = self.result.summary
        self.result.summary = with_failure(
            before, before['status'] if 'failure' in before else 'recording_failed',
            before.get('failure', line))
        try:
            self.written.append(write_text(summary, json_text(self.result.summary)))
        except OSError as again:
            self.get_logger().error(write_error(again))

    def peer_died(self) -> None:
        """End the run with status ``failed``: a supervisor saw another process of the run
        die (:data:`~flock_swarm.console.FAIL_SIGNAL`); keep what was recorded."""
        self.fail(f'another process of the run died (the supervisor said so at step {self.k})')

    def close(self) -> None:
        """Called on shutdown: keep what was recorded (status ``interrupted``), and let the
        announcement of the end reach the leader and agents before the node goes."""
        if self.refusal is not None:
            # Announce nothing on swarm/status: the other world's leader and agents hear it.
            # Leave no bag behind either (it holds nothing of a run): out_dir can be reused.
            self.stepper.end('refused')
            for sink in self.sinks:
                sink.close()
            self.spool.discard()
            if self.bag is not None:
                shutil.rmtree(self.bag.path, ignore_errors=True)
            return
        if self.stepper.end('interrupted'):
            self.write_results()
        self.status_pub.wait_for_all_acked(Duration(seconds=2))

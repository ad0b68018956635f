"""The person tracker alone: checks, gating, late detections, prediction, loss and reacquiry,
and the filter's consistency on a noisy walk."""

import dataclasses
import math

import numpy as np
import pytest

from companion.params import SensingParams, TrackerParams
from companion.tracking import (
    PersonTracker,
    coordinated_turn,
    exact_detection,
    predict,
    process_noise,
)
from companion.types import PersonDetection, PersonState, Pose

TP = TrackerParams()


def seen(t, x, y, frame="world", **kw):
    return PersonDetection(t, x, y, frame, **kw)


def walk(tracker, times, path, noise=0.0, rng=None, now_lag=0.0):
    """Feed one detection per time of ``path(t) -> (x, y)``; return the last estimate."""
    for t in times:
        x, y = path(t)
        if noise:
            x, y = x + noise * rng.standard_normal(), y + noise * rng.standard_normal()
        tracker.add([seen(t, x, y)], t + now_lag)
    return tracker.estimate(times[-1] + now_lag)


def straight(t):
    return 1.2 * t, 0.5


def test_predict_follows_the_unicycle_arc():
    h = PersonState(0.0, 0.0, 0.0, 1.0, 0.5)
    q = predict(h, math.pi / 0.5)            # half a circle of radius 2
    assert (q.x, q.y) == pytest.approx((0.0, 4.0), abs=1e-9)
    assert predict(PersonState(1.0, 2.0, 0.0, 1.0, 0.0), 2.0).x == pytest.approx(3.0)
    turned = coordinated_turn(np.array((0.0, 0.0, 1.0, 0.0, 0.5)), math.pi / 0.5)
    assert turned == pytest.approx((0.0, 4.0, -1.0, 0.0, 0.5), abs=1e-9)


def test_process_noise_is_symmetric_positive_semidefinite_and_grows_with_time():
    q1, q2 = process_noise(0.1, 0.3, 1.5), process_noise(0.2, 0.3, 1.5)
    assert np.allclose(q1, q1.T)
    assert np.min(np.linalg.eigvalsh(q1)) >= -1e-15
    assert np.all(np.diag(q2) > np.diag(q1))


def test_an_exact_detection_sets_the_whole_state_exactly():
    tr = PersonTracker(TP)
    h = PersonState(1.0, 2.0, 0.3, 1.1, -0.2)
    tr.add([exact_detection(0.0, h)], 0.0)
    e = tr.estimate(0.0)
    assert e.state == h and e.position_std == 0.0 and e.status == "seen"
    later = tr.estimate(0.1)                # predicted exactly along the arc
    assert later.state.x == pytest.approx(predict(h, 0.1).x, abs=1e-12)


def test_noise_free_positions_give_speed_and_heading():
    tr = PersonTracker(TP)
    e = walk(tr, np.arange(0.0, 4.0, 0.1), straight)    # from a standing start: v = 0
    assert e.state.v == pytest.approx(1.2, abs=0.02)
    assert e.state.theta == pytest.approx(0.0, abs=0.01)
    assert (e.state.x, e.state.y) == pytest.approx((1.2 * 3.9, 0.5), abs=0.005)


def test_a_turning_walker_gives_its_turn_rate():
    tr = PersonTracker(TP)
    omega, r = 0.5, 2.0

    def circle(t):
        return r * math.sin(omega * t), r * (1.0 - math.cos(omega * t))

    e = walk(tr, np.arange(0.0, 6.0, 0.1), circle)
    assert e.state.omega == pytest.approx(omega, abs=0.03)
    assert e.state.v == pytest.approx(omega * r, abs=0.03)


def test_noisy_walk_estimates_are_consistent_with_their_covariance():
    """On a walk with 5 cm noise the position error stays within what the covariance says
    (normalised estimation error squared: mean near 2, rarely above the 99 % bound)."""
    rng = np.random.default_rng(3)
    tr = PersonTracker(TP)
    nees, err = [], []
    for t in np.arange(0.0, 30.0, 0.1):
        x, y = _curvy(t) + 0.05 * rng.standard_normal(2)
        tr.add([seen(t, x, y)], t)
        e = tr.estimate(t)
        if t > 2.0:
            d = np.array((e.state.x, e.state.y)) - _curvy(t)
            nees.append(float(d @ np.linalg.solve(e.covariance[:2, :2], d)))
            err.append(math.hypot(*d))
    assert np.sqrt(np.mean(np.square(err))) < 0.05          # better than one raw detection
    assert 0.5 < np.mean(nees) < 4.0
    assert np.mean(np.array(nees) > 9.21) < 0.05


def _curvy(t):
    return np.array((1.1 * t, 0.8 * math.sin(0.3 * t)))


@pytest.mark.parametrize("bad, reason", [
    (seen(math.nan, 0.0, 0.0), "person_invalid"),
    (seen(1.0, math.inf, 0.0), "person_invalid"),
    (seen(1.0, 0.0, 0.0, heading=math.nan), "person_invalid"),
    (seen(1.0, 1e300, 0.0), "person_invalid"),                   # finite but absurd
    (seen(2.0, 1.2, 0.5), "detection_future"),
    (seen(0.2, 0.24, 0.5), "detection_stale"),
    (seen(1.0, 1.2, 0.5, frame="camera"), "detection_frame"),
])
def test_bad_detections_are_rejected_with_a_reason(bad, reason):
    tr = PersonTracker(TP)
    walk(tr, np.arange(0.0, 0.91, 0.1), straight)
    before = tr.estimate(1.0)
    reasons = []
    tr.add([bad], 1.0, reasons=reasons)
    assert reasons == [reason]
    assert tr.estimate(1.0).state == before.state


def test_robot_frame_detections_use_the_pose_at_their_time():
    tr = PersonTracker(TP)
    robot = Pose(1.0, 2.0, math.pi / 2)          # facing +y
    tr.add([seen(0.0, 1.0, 0.5, frame="robot", covariance=(0.04, 0.0, 0.0, 0.0001))], 0.0,
           pose_at=lambda t: robot)
    e = tr.estimate(0.0)
    assert (e.state.x, e.state.y) == pytest.approx((0.5, 3.0))
    # the covariance turns with the frame: the robot's x (large) is the world's y
    assert e.covariance[1, 1] > 100 * e.covariance[0, 0]


def test_a_robot_frame_detection_without_a_valid_robot_pose_is_rejected():
    tr = PersonTracker(TP)
    reasons = []
    tr.add([seen(0.0, 1.0, 0.5, frame="robot")], 0.0,
           pose_at=lambda t: Pose(math.nan, math.nan, math.nan), reasons=reasons)
    assert reasons == ["person_invalid"] and tr.estimate(0.0) is None


def test_another_person_is_gated_out_and_the_nearest_detection_is_taken():
    tr = PersonTracker(TP)
    walk(tr, np.arange(0.0, 2.0, 0.1), straight)
    reasons = []
    tr.add([seen(2.0, 2.4, 2.5)], 2.0, reasons=reasons)        # 2 m to the side: someone else
    assert reasons == ["person_outlier"]
    tr.add([seen(2.1, 2.52, 1.5), seen(2.1, 2.52, 0.5)], 2.1)   # two people: the nearer wins
    assert tr.estimate(2.1).state.y == pytest.approx(0.5, abs=0.02)


def test_late_and_out_of_order_detections_give_the_in_order_estimate():
    rng = np.random.default_rng(0)
    times = np.arange(0.0, 4.0, 0.1)
    dets = [seen(t, *(np.array(straight(t)) + 0.03 * rng.standard_normal(2))) for t in times]
    in_order = PersonTracker(TP)
    for d in dets:
        in_order.add([d], d.t)
    shuffled = PersonTracker(TP)
    shuffled.add([dets[0]], 0.0)
    for k in range(1, len(dets) - 1, 2):          # pairs arrive swapped, one period late
        shuffled.add([dets[k + 1], dets[k]], dets[k + 1].t)
    shuffled.add([dets[-1]], dets[-1].t)
    a, b = in_order.estimate(4.0), shuffled.estimate(4.0)
    assert np.allclose((a.state.x, a.state.y, a.state.v), (b.state.x, b.state.y, b.state.v),
                       atol=1e-9)


def test_dropout_is_predicted_then_the_person_is_lost_and_reacquired():
    tr = PersonTracker(TP)
    walk(tr, np.arange(0.0, 4.05, 0.1), straight)      # last detection at t = 4.0
    reasons = []
    e = tr.estimate(4.2, reasons)
    assert e.status == "seen" and reasons == []
    e = tr.estimate(4.4, reasons)
    assert e.status == "predicted" and "person_predicted" in reasons
    assert e.state.x == pytest.approx(1.2 * 4.4, abs=0.01)    # carried on at its speed
    assert tr.estimate(4.0 + TP.lost_after_s + 0.01) is None and tr.lost
    tr.add([seen(5.0, 6.0, 0.5)], 5.0)
    assert tr.reacquiring and tr.estimate(5.0) is None
    for t in np.arange(5.1, 5.0 + TP.reacquire_time_s + 0.01, 0.1):
        tr.add([seen(t, 1.2 * t, 0.5)], t)
    assert tr.reacquired and not tr.lost
    assert tr.estimate(5.3).state.x == pytest.approx(1.2 * 5.3, abs=0.05)


def test_a_re_find_whose_detections_stop_is_a_loss_again_not_a_wait():
    """One detection where the lost person may be begins a re-find; if no other follows
    within ``lost_after_s`` the tracker is plainly lost again (the supervisor searches) instead
    of waiting for ever for the re-find's next detection (a person at the edge of the
    detector's range: one detection, then none)."""
    tr = PersonTracker(TP)
    walk(tr, np.arange(0.0, 4.05, 0.1), straight)
    assert tr.estimate(4.0 + TP.lost_after_s + 0.01) is None and tr.lost
    tr.add([seen(5.0, 6.0, 0.5)], 5.0)
    assert tr.estimate(5.0 + TP.lost_after_s - 0.01) is None and tr.reacquiring
    assert tr.estimate(5.0 + TP.lost_after_s + 0.01) is None
    assert tr.lost and not tr.reacquiring


def test_inconsistent_detections_do_not_reacquire():
    tr = PersonTracker(TP)
    walk(tr, np.arange(0.0, 1.05, 0.1), straight)
    assert tr.estimate(2.0) is None
    for k, t in enumerate(np.arange(2.0, 4.0, 0.1)):    # two places 3 m apart, alternating,
        tr.add([seen(t, 1.2 * t, 0.5 + 3.0 * (k % 2 - 0.5))], t)   # both where it may be
    assert tr.lost and not tr.reacquired


def test_a_person_who_stops_keeps_facing_the_way_they_walked():
    tr = PersonTracker(TP)
    walk(tr, np.arange(0.0, 3.0, 0.1), lambda t: (t * math.cos(0.8), t * math.sin(0.8)))
    stop = (2.9 * math.cos(0.8), 2.9 * math.sin(0.8))
    rng = np.random.default_rng(1)
    for t in np.arange(3.0, 8.0, 0.1):
        tr.add([seen(t, *(np.array(stop) + 0.02 * rng.standard_normal(2)))], t)
    e = tr.estimate(7.9)
    assert e.state.v < TP.standing_speed
    assert e.walker.theta == pytest.approx(0.8, abs=0.15)
    assert e.walker.v == 0.0 and e.walker.omega == 0.0


def test_an_uncertain_track_is_reported():
    tr = PersonTracker(TrackerParams(uncertain_std_m=0.05, position_std_m=0.1))
    reasons = []
    tr.add([seen(0.0, 0.0, 0.0)], 0.0)
    assert tr.estimate(0.0, reasons).position_std == pytest.approx(0.1, rel=1e-3)
    assert reasons == ["person_uncertain"]


def test_a_clock_that_goes_back_past_the_track_loses_the_person_instead_of_raising():
    tr = PersonTracker(TP)
    tr.add([exact_detection(1e308, PersonState(0.0, 0.0, 0.0, 0.0, 3.0))], 1e308)
    assert tr.estimate(1e308) is not None
    assert tr.estimate(1.0) is None and tr.lost
    walk(tr, np.arange(2.0, 3.0, 0.1), straight)          # a new track can start again
    assert tr.estimate(2.9) is not None and not tr.lost


def test_exact_parts_that_contradict_the_track_never_raise():
    """Detections with an 'exact' heading (std 0) that contradicts the walk (a driver that
    fills an unknown heading with 0) make the innovation covariance singular; the filter
    skips that model's update instead of raising out of the step (before: 49 of 200 such
    walks raised ValueError)."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        tr = PersonTracker(TP)
        for t in np.arange(0.0, 4.0, 0.1):
            x, y = 1.2 * t * math.cos(0.5), 1.2 * t * math.sin(0.5)
            exact_heading = {"heading": 0.0, "heading_std": 0.0} if t >= 1.0 else {}
            tr.add([seen(t, x + 0.05 * rng.standard_normal(), y + 0.05 * rng.standard_normal(),
                         covariance=(0.0025, 0.0, 0.0, 0.0025), **exact_heading)], t)
            e = tr.estimate(t)
            assert e is None or (np.all(np.isfinite(e.covariance)) and math.isfinite(e.state.x))


def _sharp_turn(t):
    """1.4 m/s along x, then from t = 3 s along y: a turn no walker model expects."""
    return np.array((1.4 * t, 0.0)) if t < 3.0 else np.array((4.2, 1.4 * (t - 3.0)))


def _follow(params, path, seed=5, until=8.0):
    """(t, estimate) per 10 Hz detection of ``path`` with 5 cm noise."""
    rng, tr, out = np.random.default_rng(seed), PersonTracker(params), []
    for t in np.arange(0.0, until, 0.1):
        x, y = path(t) + 0.05 * rng.standard_normal(2)
        tr.add([seen(t, x, y)], t)
        out.append((t, tr.estimate(t)))
    return out


def test_a_manoeuvre_widens_the_reported_uncertainty_but_not_the_filter():
    """A sharp turn leaves the estimate lagging by 0.2 m; the plain filter reports about 0.04 m
    (over 5 std off), the widened one covers the lag within about 2 std. The means are the
    same, and on the straight walk the widening stays moderate."""
    plain = _follow(TrackerParams(inflate_nis=math.inf), _sharp_turn)
    wide = _follow(TP, _sharp_turn)
    ratio = {}
    for name, run in (("plain", plain), ("wide", wide)):
        ratio[name] = max(math.hypot(*(np.array((e.state.x, e.state.y)) - _sharp_turn(t)))
                          / e.position_std for t, e in run if 3.0 <= t < 4.5)
    assert ratio["plain"] > 4.0
    assert ratio["wide"] < 3.0
    for (_, a), (_, b) in zip(plain, wide):
        assert (a.state.x, a.state.y, a.state.v) == (b.state.x, b.state.y, b.state.v)
        assert b.position_std >= a.position_std
        assert b.covariance[2:, 2:] == pytest.approx(a.covariance[2:, 2:])
        assert np.all(np.linalg.eigvalsh(b.covariance) > -1e-12)
    steady = [b.position_std / a.position_std for (t, a), (_, b) in zip(plain, wide)
              if 1.0 <= t < 3.0]
    assert 1.0 <= np.median(steady) < 1.6


def _gently_curving(t):
    """A walker at 1.2 m/s turning at 0.1 rad/s: what the steady model expects."""
    return np.array((12.0 * math.sin(0.1 * t), 12.0 * (1.0 - math.cos(0.1 * t))))


def _noisy_walk(params, noise, declared, sensing=None, seed=3, until=60.0):
    """The tracker after 10 Hz detections of :func:`_gently_curving` with ``noise`` m of
    noise whose covariance states ``declared`` m (None: no covariance); the NIS of the
    second half."""
    rng, tr, nis = np.random.default_rng(seed), PersonTracker(params, sensing), []
    cov = None if declared is None else (declared ** 2, 0.0, 0.0, declared ** 2)
    for t in np.arange(0.0, until, 0.1):
        x, y = _gently_curving(t) + noise * rng.standard_normal(2)
        tr.add([seen(t, x, y, covariance=cov)], t)
        if t >= until / 2:
            nis += tr.innovations
    return tr, np.array(nis)


def test_the_innovations_of_an_honest_detector_are_chi_square():
    """Declared noise equal to the real one: the NIS's mean lies near its 2 degrees of
    freedom (a gently turning walker; the process noise allows for more, so a little below)
    and few exceed its 95 % point."""
    _, nis = _noisy_walk(TP, 0.05, 0.05)
    assert 1.4 < nis.mean() < 2.4
    assert np.mean(nis > 5.99) < 0.08


def test_a_detector_noisier_than_it_declares_is_learned_within_bounds():
    """10 cm of noise declared as 5 cm: the fixed filter's NIS is far above 2; adapting, the
    tracker learns a factor near the true 4 on the variance, within its bound, and the NIS
    comes back near 2. With an honest detector the factor stays near 1."""
    adaptive = dataclasses.replace(TP, adapt_noise_max=5.0, adapt_time_s=2.0)
    fixed, nis_fixed = _noisy_walk(TP, 0.10, 0.05)
    assert fixed.noise_scale == 1.0 and nis_fixed.mean() > 4.0
    learned, nis = _noisy_walk(adaptive, 0.10, 0.05)
    assert 2.5 < learned.noise_scale <= 5.0
    assert 1.4 < nis.mean() < 2.8
    capped, _ = _noisy_walk(dataclasses.replace(adaptive, adapt_noise_max=2.0), 0.10, 0.05)
    assert capped.noise_scale <= 2.0
    honest, _ = _noisy_walk(adaptive, 0.05, 0.05)
    assert 1.0 <= honest.noise_scale < 1.8


def test_detections_without_covariance_take_the_declared_sensing_noise():
    """A PointStamped-like detection: its noise is the sensing profile's unless the tracker
    is given one, and the NIS is honest with it."""
    noisy = SensingParams(person_position_noise_m=0.2)
    assert PersonTracker(TP, noisy).params.position_std_m == 0.2
    assert PersonTracker(TrackerParams(position_std_m=0.07), noisy).params.position_std_m \
        == 0.07
    assert PersonTracker(TP, SensingParams(person_position_noise_m=0.2,
                                           person_declared_noise_m=0.1)
                         ).params.position_std_m == 0.1
    assert PersonTracker(TP, SensingParams(person_heading_noise_rad=0.02)
                         ).params.heading_std_rad == 0.02
    _, nis = _noisy_walk(TP, 0.10, None, SensingParams(person_position_noise_m=0.10))
    assert 1.4 < nis.mean() < 2.4


def lose_at_four(tr):
    """A walk along y = 0.5 at 1.2 m/s, seen until t = 4.0, then lost."""
    walk(tr, np.arange(0.0, 4.05, 0.1), straight)
    assert tr.estimate(4.0 + TP.lost_after_s + 0.01) is None and tr.lost


def test_a_person_is_refound_only_where_the_lost_track_could_have_gone():
    far = PersonTracker(TP)
    lose_at_four(far)
    for t in np.arange(5.0, 6.0, 0.1):                 # someone 6 m to the side, steadily
        far.add([seen(t, 1.2 * t, 6.5)], t)
    assert far.lost and far.estimate(5.9) is None
    near = PersonTracker(TP)
    lose_at_four(near)
    for t in np.arange(5.0, 6.0, 0.1):                 # the person, where they were going
        near.add([seen(t, 1.2 * t, 0.5)], t)
    assert not near.lost and near.estimate(5.9).state.x == pytest.approx(1.2 * 5.9, abs=0.05)


def test_the_reidentification_hook_decides_where_it_says_so():
    asked = []

    def hook(d, last):
        asked.append((d.t, last.x))
        return d.y > 5.0 if d.y != 0.5 else None      # the one 6 m away is the person

    tr = PersonTracker(TP, reidentify=hook)
    lose_at_four(tr)
    for t in np.arange(5.0, 5.6, 0.1):
        tr.add([seen(t, 1.2 * t, 6.5)], t)
    assert not tr.lost and tr.estimate(5.5).state.y == pytest.approx(6.5, abs=0.05)
    assert asked and asked[0][1] == pytest.approx(1.2 * 4.0, abs=0.05)   # the last track

    refuses = PersonTracker(TP, reidentify=lambda d, last: False)
    lose_at_four(refuses)
    for t in np.arange(5.0, 6.0, 0.1):                 # consistent with the prediction, but no
        refuses.add([seen(t, 1.2 * t, 0.5)], t)
    assert refuses.lost


def test_a_failing_hook_is_reported_and_the_prediction_decides():
    def broken(d, last):
        raise RuntimeError("camera gone")

    tr = PersonTracker(TP, reidentify=broken)
    lose_at_four(tr)
    reasons = []
    for t in np.arange(5.0, 5.6, 0.1):
        tr.add([seen(t, 1.2 * t, 0.5)], t, reasons=reasons)
    assert "reidentify_failed" in reasons and not tr.lost


def test_detections_of_other_people_are_handed_on():
    tr = PersonTracker(TP)
    walk(tr, np.arange(0.0, 2.0, 0.1), straight)
    other = seen(2.0, 4.0, 3.0)
    tr.add([seen(2.0, 2.4, 0.5), other], 2.0)
    assert tr.others == [other]
    tr.add([seen(2.1, 2.52, 0.5)], 2.1)
    assert tr.others == []

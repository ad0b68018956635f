"""The Gymnasium environment: the checker passes, a seed repeats an episode, and the reward
says how well a policy keeps the slot."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import companion.sim.gym_env  # noqa: F401  (registers companion/Follow-v0)
from companion.control import make_controller
from companion.sim.gym_env import OBSERVATION, FollowEnv
from companion.types import Command

#: The observation is unbounded (positions in a world without walls) and the action is in SI
#: units (m/s, rad/s), not normalised to [-1, 1]; the checker notes both.
pytestmark = [pytest.mark.filterwarnings("ignore:.*Box observation space:UserWarning"),
              pytest.mark.filterwarnings("ignore:.*symmetric and normalized space:UserWarning")]


@pytest.mark.parametrize("sensing, plant", [("ideal", "kinematic"), ("realistic", "kinematic"),
                                             ("realistic", "mujoco")])
def test_the_gymnasium_checker_passes(sensing, plant):
    env = gym.make("companion/Follow-v0", scenario="line", sensing=sensing, duration=3.0,
                   plant=plant)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (len(OBSERVATION),) and env.observation_space.contains(obs)


def _episode(env, policy, seed):
    obs, info = env.reset(seed=seed)
    rewards, observations = [], [obs]
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy(obs, info))
        rewards.append(reward)
        observations.append(obs)
        done = terminated or truncated
    return np.array(rewards), np.array(observations), terminated


def test_a_seed_repeats_the_episode():
    env = FollowEnv("figure8", "realistic", duration=4.0)
    still = lambda obs, info: np.zeros(2)  # noqa: E731
    a, oa, _ = _episode(env, still, 5)
    b, ob, _ = _episode(env, still, 5)
    _, oc, _ = _episode(env, still, 6)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(oa, ob)
    assert not np.array_equal(oa, oc)         # other sensing noise


def test_the_companion_stack_as_a_policy_earns_more_than_standing_still():
    """The LQR stack driven through the environment (its own observation in ``info``) keeps
    the slot: mean reward above -0.05 m; standing still loses the person: below -1 m."""
    env = FollowEnv("figure8", "ideal", duration=20.0)
    stack = make_controller("lqr", env.params)

    def lqr(obs, info):
        if "start_velocity" in info:          # the first step of an episode
            stack.reset()
            stack.applied(Command(*info["start_velocity"]))
        cmd = stack.step(info["observation"])
        return np.array((cmd.v, cmd.omega))

    rewards, _, terminated = _episode(env, lqr, 0)
    assert not terminated and len(rewards) == 400
    assert rewards.mean() > -0.05
    still, _, _ = _episode(env, lambda obs, info: np.zeros(2), 0)
    assert still.mean() < -1.0


@pytest.mark.parametrize("action, message", [
    (np.array((np.nan, 0.0)), "finite"), (np.array((0.5, np.inf)), "finite"),
    (np.array((0.5,)), r"shape \(2,\)"), (np.array((0.5, 0.0, 0.1)), r"shape \(2,\)"),
    (0.5, r"shape \(2,\)")])
def test_a_malformed_action_is_refused_and_simulates_nothing(action, message):
    env = FollowEnv("line", "ideal", duration=3.0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(action)
    obs, reward, terminated, truncated, info = env.step(np.zeros(2))  # the episode goes on
    assert np.all(np.isfinite(obs)) and np.isfinite(reward) and not (terminated or truncated)
    assert info["observation"].t == pytest.approx(env.params.dt)


def test_an_action_outside_the_box_is_clipped():
    env = FollowEnv("line", "ideal", duration=3.0)
    env.reset(seed=0)
    *_, fast = env.step(np.array((100.0, -100.0)))
    env.reset(seed=0)
    *_, limit = env.step(env.action_space.low * (-1.0, 1.0))
    assert fast["row"] == limit["row"]

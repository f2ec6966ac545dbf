"""agents/xla_flags.py: which XLA_FLAGS the project sets, and when it leaves them alone."""

import pathlib

import jax
import pytest

from agents import xla_flags

FLAG = "--xla_gpu_command_buffer_scheduling_mode"
LOOPS = "--xla_gpu_enable_command_buffer"
DEFAULTS = FLAG + "=CONCURRENT " + LOOPS + "=+WHILE"


@pytest.mark.parametrize("before, after", [
    ("", DEFAULTS),  # nothing set: both defaults
    ("--xla_force_host_platform_device_count=2", "--xla_force_host_platform_device_count=2 " + DEFAULTS),  # kept
    (FLAG + "=LHS", FLAG + "=LHS " + LOOPS + "=+WHILE"),  # the user's scheduling mode wins, the loops flag added
    (LOOPS + "=FUSION", LOOPS + "=FUSION " + FLAG + "=CONCURRENT"),  # the user's command buffer types win
])
def test_adds_the_defaults_a_gpu_machines_flags_lack(before, after):
    env = {"XLA_FLAGS": before}
    assert xla_flags.apply(env, gpu=True)
    assert env["XLA_FLAGS"] == after


def test_a_second_apply_changes_nothing():
    env = {}
    xla_flags.apply(env, gpu=True)
    assert not xla_flags.apply(env, gpu=True)


def test_the_users_choice_of_both_flags_is_left_alone():
    mine = {"XLA_FLAGS": FLAG + "=LHS " + LOOPS + "=FUSION"}
    assert not xla_flags.apply(mine, gpu=True)
    assert mine["XLA_FLAGS"] == FLAG + "=LHS " + LOOPS + "=FUSION"


def test_the_opt_out_leaves_xla_flags_alone():
    opted_out = {"REACH_AVOID_XLA_DEFAULTS": "0"}
    assert not xla_flags.apply(opted_out, gpu=True)
    assert "XLA_FLAGS" not in opted_out


def test_a_cpu_machine_leaves_xla_flags_alone():
    cpu = {"XLA_FLAGS": ""}
    assert not xla_flags.apply(cpu, gpu=False)
    assert cpu["XLA_FLAGS"] == ""


@pytest.fixture
def cache_setting():
    """Restores JAX's compilation cache folder after the test."""
    before = jax.config.jax_compilation_cache_dir, jax.config.jax_compilation_cache_max_size
    yield
    jax.config.update("jax_compilation_cache_dir", before[0])
    jax.config.update("jax_compilation_cache_max_size", before[1])


@pytest.mark.parametrize("path, environ, folder", [
    (None, {}, xla_flags.DEFAULT_CACHE),  # nothing named: the checkout's .jax_cache/
    (None, {"JAX_COMPILATION_CACHE_DIR": "/tmp/elsewhere"}, "/tmp/elsewhere"),  # JAX's own variable wins
    (None, {"JAX_COMPILATION_CACHE_DIR": ""}, None),  # set empty: no cache
    ("/tmp/given", {"JAX_COMPILATION_CACHE_DIR": "/tmp/elsewhere"}, "/tmp/given"),  # an explicit path wins
    ("off", {}, None),
])
def test_compilation_cache_folder(cache_setting, path, environ, folder):
    assert xla_flags.compilation_cache(path, environ) == folder
    assert jax.config.jax_compilation_cache_dir == folder


def test_the_default_cache_is_a_folder_git_ignores():
    root = pathlib.Path(__file__).resolve().parents[1]
    assert f"/{pathlib.Path(xla_flags.DEFAULT_CACHE).relative_to(root)}/" in (root / ".gitignore").read_text().split()


@pytest.mark.parametrize("environ, limit", [
    ({}, xla_flags.CACHE_BYTES),  # bounded: least recently used programs go first
    ({"JAX_COMPILATION_CACHE_MAX_SIZE": "123"}, 123),  # JAX's own variable, as JAX read it at import: left alone
])
def test_the_cache_has_a_size_limit_unless_one_is_set(cache_setting, environ, limit):
    jax.config.update("jax_compilation_cache_max_size", int(environ.get("JAX_COMPILATION_CACHE_MAX_SIZE", -1)))
    xla_flags.compilation_cache("off", environ)
    assert jax.config.jax_compilation_cache_max_size == limit

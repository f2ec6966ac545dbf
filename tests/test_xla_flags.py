"""agents/xla_flags.py: which XLA_FLAGS the project sets, and when it leaves them alone."""

import pathlib

import jax
import pytest

from agents import xla_flags

FLAG = "--xla_gpu_command_buffer_scheduling_mode"
LOOPS = "--xla_gpu_enable_command_buffer"
DEFAULTS = FLAG + "=CONCURRENT " + LOOPS + "=+WHILE"


def test_adds_the_flag_on_a_gpu_machine_and_keeps_the_users_flags():
    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    assert xla_flags.apply(env, gpu=True)
    assert env["XLA_FLAGS"] == "--xla_force_host_platform_device_count=2 " + DEFAULTS
    assert not xla_flags.apply(env, gpu=True)  # already there: unchanged
    assert env["XLA_FLAGS"].count(FLAG) == 1
    fresh = {}
    assert xla_flags.apply(fresh, gpu=True)
    assert fresh["XLA_FLAGS"] == DEFAULTS


def test_the_users_choice_the_opt_out_and_cpu_machines_leave_xla_flags_alone():
    mine = {"XLA_FLAGS": FLAG + "=LHS " + LOOPS + "=FUSION"}
    assert not xla_flags.apply(mine, gpu=True)
    assert mine["XLA_FLAGS"] == FLAG + "=LHS " + LOOPS + "=FUSION"
    one_of_mine = {"XLA_FLAGS": FLAG + "=LHS"}
    assert xla_flags.apply(one_of_mine, gpu=True)
    assert one_of_mine["XLA_FLAGS"] == FLAG + "=LHS " + LOOPS + "=+WHILE"  # the other default still added
    opted_out = {"REACH_AVOID_XLA_DEFAULTS": "0"}
    assert not xla_flags.apply(opted_out, gpu=True)
    assert "XLA_FLAGS" not in opted_out
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

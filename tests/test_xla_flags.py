"""agents/xla_flags.py: which XLA_FLAGS the project sets, and when it leaves them alone."""

from agents import xla_flags

FLAG = "--xla_gpu_command_buffer_scheduling_mode"


def test_adds_the_flag_on_a_gpu_machine_and_keeps_the_users_flags():
    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    assert xla_flags.apply(env, gpu=True)
    assert env["XLA_FLAGS"] == "--xla_force_host_platform_device_count=2 " + FLAG + "=CONCURRENT"
    assert not xla_flags.apply(env, gpu=True)  # already there: unchanged
    assert env["XLA_FLAGS"].count(FLAG) == 1
    fresh = {}
    assert xla_flags.apply(fresh, gpu=True)
    assert fresh["XLA_FLAGS"] == FLAG + "=CONCURRENT"


def test_the_users_choice_the_opt_out_and_cpu_machines_leave_xla_flags_alone():
    mine = {"XLA_FLAGS": FLAG + "=LHS"}
    assert not xla_flags.apply(mine, gpu=True)
    assert mine["XLA_FLAGS"] == FLAG + "=LHS"
    opted_out = {"REACH_AVOID_XLA_DEFAULTS": "0"}
    assert not xla_flags.apply(opted_out, gpu=True)
    assert "XLA_FLAGS" not in opted_out
    cpu = {"XLA_FLAGS": ""}
    assert not xla_flags.apply(cpu, gpu=False)
    assert cpu["XLA_FLAGS"] == ""


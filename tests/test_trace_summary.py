"""benchmarks.trace_summary on a hand-made trace whose totals are known."""

import datetime
import gzip
import json
import shlex
import sys

from benchmarks import trace_summary as ts

HLO = """
HloModule jit_chunk
%body {
  %loop_add_fusion.12 = f32[8]{0} fusion(%p), kind=kLoop, calls=%f1, metadata={op_name="jit(chunk)/while/body/env_step/vmap()/add" stack_frame_id=3}
  %gemm_fusion_dot.3 = f32[8,4]{1,0} fusion(%q), kind=kCustom, calls=%f2, metadata={op_name="jit(chunk)/while/body/update/while/body/sgd_step/dot_general" stack_frame_id=4}
  ROOT %cholesky.95 = f32[8,6,6]{2,1,0} custom-call(%r), custom_call_target="cusolver", metadata={op_name="jit(chunk)/while/body/env_step/step/cholesky"}
}
"""


def _trace(tmp_path):
    gpu, host = 1, 701
    x = lambda pid, ts_, dur, name, **args: {"ph": "X", "pid": pid, "tid": 1, "ts": ts_, "dur": dur, "name": name, "args": args}
    events = [
        {"ph": "M", "pid": gpu, "name": "process_name", "args": {"name": "/device:GPU:0"}},
        {"ph": "M", "pid": host, "name": "process_name", "args": {"name": "/host:CPU"}},
        # inside a CUDA graph: the hlo_op names the graph, the kernel name is the fusion's
        # (graph 7 launched twice: each launch's kernels share its correlation id)
        x(gpu, 0.0, 10.0, "loop_add_fusion_12", hlo_op="command_buffer_7", cuda_graph_id="7", correlation_id="1"),
        x(gpu, 5.0, 10.0, "loop_add_fusion_12", hlo_op="command_buffer_7", cuda_graph_id="7", correlation_id="2"),
        x(gpu, 30.0, 4.0, "potrf_kernel", hlo_op="cholesky.95"),                # a library call outside graphs
        x(gpu, 40.0, 6.0, "gemm_fusion_dot_3", hlo_op="command_buffer_9", cuda_graph_id="9", correlation_id="3"),
        x(gpu, 50.0, 2.0, "memcpy32_post", hlo_op="command_buffer_9", cuda_graph_id="9", correlation_id="3"),  # "other"
    ] + [x(host, float(i), 3.0, "cuGraphLaunch") for i in range(10)] + [x(host, 0.0, 50.0, "$python frame")]
    with gzip.open(tmp_path / "perfetto_trace.json.gz", "wt") as f:
        json.dump({"traceEvents": events}, f)
    (tmp_path / "chunk.hlo.txt").write_text(HLO)


def test_busy_time_is_the_union_of_intervals():
    assert ts.busy_time([(0, 10), (5, 15), (30, 34), (31, 32)]) == 19


def test_summary_of_a_known_trace(tmp_path):
    _trace(tmp_path)
    events, names = ts.load_events(tmp_path)
    hlo_names = ts.op_names((tmp_path / "chunk.hlo.txt").read_text())
    assert hlo_names["loop_add_fusion_12"].endswith("env_step/vmap()/add")
    summary = ts.summarize(events, names, ts.DEFAULT_SCOPES, top=10, hlo_names=hlo_names)
    assert list(summary) == ["/device:GPU:0"]
    d = summary["/device:GPU:0"]
    assert d["span_us"] == 52.0
    assert d["busy_us"] == 27.0
    assert d["kernels"] == 5
    assert d["scopes"] == {"env_step": {"us": 24.0, "kernels": 3}, "sgd_step": {"us": 6.0, "kernels": 1},
                           "other": {"us": 2.0, "kernels": 1}}
    assert d["top_kernels"][0] == {"name": "loop_add_fusion", "us": 20.0, "count": 2}
    host = ts.host_summary(events, names)
    assert host == [{"name": "cuGraphLaunch", "us": 30.0, "count": 10}]  # python frames and one-offs left out
    text = ts.format_summary(summary, host)
    assert "kernels busy 0.0 ms (52%)" in text
    assert "| env_step | 0.0 | 3 |" in text


def test_the_json_names_what_made_it(tmp_path, monkeypatch):
    """--json: the summary with the command, code, device (the trace's, which names no model) and date."""
    from agents import provenance

    _trace(tmp_path)
    monkeypatch.delenv(provenance.COMMAND_VARIABLE, raising=False)
    out = tmp_path / "summary.json"
    monkeypatch.setattr(sys, "argv", [ts.__file__, str(tmp_path), "--json", str(out)])
    ts.main()
    meta = json.loads(out.read_text())["meta"]
    assert meta["command"] == shlex.join(["python", "-m", "benchmarks.trace_summary", str(tmp_path),
                                          "--json", str(out)])
    assert meta["code"] == provenance.code_version()
    assert meta["device"].startswith("/device:GPU:0 of the trace")
    assert meta["date"] == datetime.date.today().isoformat()


def test_per_scope_detail_names_where_kernels_come_from(tmp_path):
    _trace(tmp_path)
    events, names = ts.load_events(tmp_path)
    hlo_names = ts.op_names((tmp_path / "chunk.hlo.txt").read_text())
    d = ts.summarize(events, names, ts.DEFAULT_SCOPES, top=10, hlo_names=hlo_names, detail=5)["/device:GPU:0"]
    env = d["scope_kernels"]["env_step"]
    # by time within the scope: the two add kernels (20 us), then the library Cholesky (4 us)
    assert [(k["name"], k["us"], k["count"]) for k in env] == [("loop_add_fusion", 20.0, 2), ("potrf_kernel", 4.0, 1)]
    assert env[0]["where"] == "jit(chunk)/while/body/env_step/vmap()/add"
    assert d["scope_kernels"]["other"] == [{"name": "memcpy32_post", "us": 2.0, "count": 1,
                                            "where": "memcpy32_post command_buffer_9"}]
    assert "### sgd_step: top kernel families" in ts.format_summary({"/device:GPU:0": d})
    assert "scope_kernels" not in ts.summarize(events, names, hlo_names=hlo_names)["/device:GPU:0"]


def test_cuda_graphs_counted_by_launch(tmp_path):
    _trace(tmp_path)
    events, names = ts.load_events(tmp_path)
    hlo_names = ts.op_names((tmp_path / "chunk.hlo.txt").read_text())
    d = ts.summarize(events, names, hlo_names=hlo_names)["/device:GPU:0"]
    # graph 7: two launches of one add kernel (20 us); graph 9: one launch of two kernels, named by the op
    # with a name stack (the 6 us GEMM; the memcpy has none); the library Cholesky runs outside graphs
    assert d["graphs"] == [
        {"graph": "7", "launches": 2, "kernels": 2, "us": 20.0, "where": "jit(chunk)/while/body/env_step/vmap()/add"},
        {"graph": "9", "launches": 1, "kernels": 2, "us": 8.0,
         "where": "jit(chunk)/while/body/update/while/body/sgd_step/dot_general"}]
    text = ts.format_summary({"/device:GPU:0": d})
    assert "| 7 | 2 | 2 | 1 | 0.0 | 10.0 | jit(chunk)/while/body/env_step/vmap()/add |" in text
    assert "| 9 | 1 | 2 | 2 | 0.0 | 8.0 |" in text


def test_a_graph_is_named_by_the_op_with_most_of_its_time():
    x = lambda ts_, dur, kernel, **args: {"ph": "X", "pid": 1, "tid": 1, "ts": ts_, "dur": dur, "name": kernel,
                                          "args": args}
    kernels = [
        # graph 3: op "a" runs twice (4 + 4 us), op "b" once (6 us), an unnamed copy 9 us and loose kernels
        # of the enclosing stack "jit(f)" 10 us: named by "a", the leaf op with most time
        x(0.0, 4.0, "f1", cuda_graph_id="3", correlation_id="1", name="jit(f)/a"),
        x(4.0, 10.0, "f0", cuda_graph_id="3", correlation_id="1", name="jit(f)"),
        x(5.0, 6.0, "f2", cuda_graph_id="3", correlation_id="1", name="jit(f)/b"),
        x(12.0, 9.0, "memcpy", cuda_graph_id="3", correlation_id="1"),
        x(22.0, 4.0, "f1", cuda_graph_id="3", correlation_id="2", name="jit(f)/a"),
        # graph 5: no op names, and one kernel without a correlation id: launches unknown
        x(30.0, 2.0, "k_small", cuda_graph_id="5", correlation_id="3"),
        x(33.0, 5.0, "k_big", cuda_graph_id="5", correlation_id="3", cuda_graph_node_id="77"),
        x(40.0, 1.0, "k_small", cuda_graph_id="5"),
    ]
    rows = ts.graph_summary(kernels, {})
    assert rows == [{"graph": "3", "launches": 2, "kernels": 5, "us": 33.0, "where": "jit(f)/a"},
                    {"graph": "5", "launches": None, "kernels": 3, "us": 8.0, "where": "k_big"}]
    text = ts.format_summary({"gpu": {"span_us": 41.0, "busy_us": 30.0, "kernels": 8, "scopes": {}, "top_kernels": [],
                                      "graphs": rows}})
    assert "| 3 | 2 | 5 | 2 | 0.0 | 16.5 | jit(f)/a |" in text
    assert "| 5 | ? | 3 | ? | 0.0 | ? | k_big |" in text

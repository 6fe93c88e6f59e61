"""linksim's public surface and its sans-I/O cores."""

from __future__ import annotations

import ast
import importlib
import pathlib

import linksim
import linksim.link

ROOT = pathlib.Path(__file__).resolve().parents[2]
FORBIDDEN = {"trio", "serial", "socket", "time", "random", "threading", "asyncio", "os", "select"}


def imports_of(path: pathlib.Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_engine_config_and_modem_are_sans_io() -> None:
    for module in ("_impair", "_config", "_modem"):
        bad = imports_of(ROOT / "linksim" / "link" / f"{module}.py") & FORBIDDEN
        assert not bad, f"linksim/link/{module}.py imports {bad}"


def test_public_names_are_pinned() -> None:
    """The short face: what most programs need; the rest is in the sub-packages."""
    assert sorted(linksim.__all__) == sorted(
        [
            "ConfigError",
            "ConsoleOptions",
            "DEFAULT_WORLD",
            "DemoOptions",
            "DirectionConfig",
            "LinkConfig",
            "ModemConfig",
            "ModemPair",
            "Outage",
            "PRESETS",
            "SimulatedArm",
            "TaskRun",
            "WorldConfig",
            "endpoint_config_for",
            "open_impaired_link",
            "rock_task",
            "run_console",
            "run_demo",
            "run_relay",
            "serial_socket_pair",
        ]
    )
    for name in linksim.__all__:
        assert getattr(linksim, name) is not None


SUB_PACKAGE_NAMES = {
    "link": [
        "CallOutcome",
        "ConfigError",
        "Cut",
        "DirectionConfig",
        "DirectionStatistics",
        "FaultAction",
        "GilbertElliott",
        "ImpairedLink",
        "LinkConfig",
        "LinkDirection",
        "LinkEnd",
        "LinkStatistics",
        "ModemConfig",
        "ModemPair",
        "ModemState",
        "ModemStateError",
        "Outage",
        "PRESETS",
        "ProxyStatistics",
        "RelayStatistics",
        "ScriptedFault",
        "TRANSITIONS",
        "TcpDirection",
        "endpoint_config_for",
        "endpoint_overrides",
        "open_impaired_link",
        "handshake_timeout_for",
        "rtt_hint_for",
        "run_proxy",
        "run_relay",
        "run_virtual",
        "serial_socket_pair",
        "server_config_for",
    ],
    "arm": [
        "ArmModel",
        "ArmStatistics",
        "DEFAULT_WORLD",
        "ObjectSpec",
        "ObstacleSpec",
        "PUMA560",
        "RockTask",
        "SimulatedArm",
        "WorldConfig",
        "hand_frame",
        "psa",
        "rock_task",
    ],
    "control": [
        "CommandRecord",
        "CommandStack",
        "CommandState",
        "ConsoleSession",
        "ConsoleSnapshot",
        "Divergence",
        "LineSource",
        "ModelState",
        "PredictedOutcome",
        "Predictor",
        "PreviewReport",
        "Progress",
        "TaskFile",
        "TaskFileError",
        "TaskRun",
        "TelemetryLog",
        "TerminalLines",
        "CommandSyntaxError",
        "feedback_record",
        "format_command",
        "load_task",
        "parse_command",
        "plot_log",
        "preview",
        "parse_log",
        "read_log",
        "render_plain",
        "resolve_task",
        "run_command_line",
        "script_lines",
    ],
    "demo": [
        "ConsoleOptions",
        "ConsoleResult",
        "DemoOptions",
        "DemoReport",
        "print_report",
        "run_console",
        "run_control",
        "run_demo",
        "run_time_limit",
        "serve_arm_serial",
        "serve_arm_tcp",
    ],
    "bench": [
        "GOODPUT_HINTS",
        "GOODPUT_PROFILES",
        "KERMIT_PAIRS",
        "LATENCY_TRANSPORTS",
        "PTY_LENGTHS",
        "PTY_PORTS",
        "Point",
        "SWEEPS",
        "SoakReport",
        "TRANSFER_ROWS",
        "TransferRow",
        "TransferSetup",
        "auto_packet_length",
        "bad_pairing",
        "check_soak",
        "cpu_count",
        "custom_grid",
        "measure_relay",
        "missing_row_keys",
        "parse_transfer_row",
        "plot_ber",
        "plot_both",
        "plot_delay",
        "plot_delay_range",
        "run_bench_kermit",
        "run_bench_pty",
        "run_codec",
        "run_flood",
        "run_goodput_transfer",
        "run_grid",
        "run_kermit_table",
        "run_kermit_transfer",
        "run_latency",
        "run_point",
        "run_soak",
        "run_transfer_table",
        "standard_grid",
        "summarize",
    ],
    "cli": [
        "build_parser",
        "main",
    ],
}


def test_sub_package_public_names_are_pinned() -> None:
    for sub, names in SUB_PACKAGE_NAMES.items():
        module = importlib.import_module(f"linksim.{sub}")
        assert sorted(module.__all__) == sorted(names), sub
        for name in names:
            assert getattr(module, name) is not None, f"linksim.{sub}.{name}"


def test_modem_transition_table_covers_every_state() -> None:
    assert set(linksim.link.TRANSITIONS) == set(linksim.link.ModemState)

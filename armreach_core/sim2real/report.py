"""The report of ``armreach sysid``: the profile, the fitted values with their spread, and plots.

:func:`write_report` writes into one folder ``profile.yaml`` (the fitted profile),
``report.json`` (every figure), ``report.md`` (a table of the values, nominal, fitted,
their spread, whether the logs identify them and why not, and the replay errors) and
``joints.png`` (per joint: logged, simulated before and simulated after the fit, on the first log).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from armreach_core.sim2real.identifiability import CHANGE
from armreach_core.sim2real.profile import randomization_ranges, save_profile
from armreach_core.sim2real.sysid import Identification


def summary(result: Identification, held_out: dict[str, tuple[float, float]] | None = None) -> dict[str, Any]:
    """Every figure of the fit, JSON-ready. ``held_out``: ``{"before"|"after": (joint rms, ee rms)}``."""
    values = {
        joint: {
            key: {
                "nominal": result.nominal.value(joint, key),
                "fitted": result.profile.value(joint, key),
                "spread": result.profile.spread.get(joint, {}).get(key),
                "identifiable": result.identifiable.get(joint, {}).get(key),
                **_verdict(result, joint, key),
            }
            for key in values
        }
        for joint, values in result.profile.joints.items()
    }
    data: dict[str, Any] = {
        "arm": result.profile.arm,
        "backend": result.profile.backend,
        "latency": result.profile.latency,
        "latency_rms_rad": {str(k): v for k, v in result.latency_rms.items()},
        "fit_rms_rad": {"before": result.rms_before, "after": result.rms_after},
        "fit_ee_rms_m": {"before": result.ee_rms_before, "after": result.ee_rms_after},
        "values": values,
        "randomize": randomization_ranges(result.profile),
    }
    if held_out:
        data["held_out_rms_rad"] = {k: v[0] for k, v in held_out.items()}
        data["held_out_ee_rms_m"] = {k: v[1] for k, v in held_out.items()}
    return data


def _verdict(result: Identification, joint: str, key: str) -> dict[str, Any]:
    verdict = result.verdicts.get(joint, {}).get(key)
    if verdict is None:
        return {}
    return {
        "rise_rad": verdict.rise,
        "held_rise_rad": verdict.held_rise,
        "resolution_rad": verdict.threshold,
        "why_not": verdict.reason,
    }


def _markdown(data: dict[str, Any]) -> str:
    lines = [
        f"# System identification: {data['arm']} on {data['backend']}",
        "",
        f"Latency: {data['latency']} control steps (replay RMS with nominal physics per latency: "
        + ", ".join(f"{k}: {v:.4f} rad" for k, v in data["latency_rms_rad"].items())
        + ").",
        "",
        "| replay error | before | after |",
        "|---|---|---|",
        f"| fitted logs, joints (rad) | {data['fit_rms_rad']['before']:.5f} | {data['fit_rms_rad']['after']:.5f} |",
        f"| fitted logs, end effector (mm) | {data['fit_ee_rms_m']['before'] * 1e3:.2f} | "
        f"{data['fit_ee_rms_m']['after'] * 1e3:.2f} |",
    ]
    if "held_out_rms_rad" in data:
        rad, ee = data["held_out_rms_rad"], data["held_out_ee_rms_m"]
        lines += [
            f"| held-out logs, joints (rad) | {rad['before']:.5f} | {rad['after']:.5f} |",
            f"| held-out logs, end effector (mm) | {ee['before'] * 1e3:.2f} | {ee['after'] * 1e3:.2f} |",
        ]
    lines += [
        "",
        "Domain randomization centred on this profile (train with `--physics` and a preset's `env.randomize`):",
        f"`{json.dumps(data['randomize'])}`.",
    ]
    lines += [
        "",
        f"Identifiable: a {CHANGE:.0%} change of the value, the joint's other values refitted, raises the replay "
        "error (rise, rad RMS over the joint's windows) at least to its resolution. A value not identifiable "
        "keeps its prior (nominal).",
        "",
        "| joint | value | nominal | fitted | spread | identifiable | rise (rad) | why not |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for joint, values in data["values"].items():
        for key, v in values.items():
            spread = "" if v["spread"] is None else f"{v['spread']:.4g}"
            judged = "" if v["identifiable"] is None else ("yes" if v["identifiable"] else "no")
            rise = f"{v['rise_rad']:.1e}" if "rise_rad" in v else ""
            lines.append(
                f"| {joint} | {key} | {v['nominal']:.4g} | {v['fitted']:.4g} | {spread} | {judged} | {rise} | "
                f"{v.get('why_not', '')} |"
            )
    return "\n".join(lines) + "\n"


def _plot(result: Identification, joint_names: tuple[str, ...], path: Path) -> None:
    from armreach_core.plotting import pyplot as plt

    logged, before, after = result.traces[0]
    figure, axes = plt.subplots(len(joint_names), 1, figsize=(10, 1.8 * len(joint_names)), sharex=True, squeeze=False)
    for i, (axis, name) in enumerate(zip(axes[:, 0], joint_names, strict=True)):
        axis.plot(logged[:, i], color="black", lw=1.2, label="logged")
        axis.plot(before[:, i], color="tab:red", lw=0.8, ls="--", label="simulated, before")
        axis.plot(after[:, i], color="tab:blue", lw=0.8, label="simulated, after")
        axis.set_ylabel(f"{name}\n(rad)", fontsize=7)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("control step")
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)


def write_report(
    result: Identification,
    out: Path,
    joint_names: tuple[str, ...],
    held_out: dict[str, tuple[float, float]] | None = None,
) -> list[Path]:
    """Write the profile and the report into ``out``; the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    data = summary(result, held_out)
    paths = [
        save_profile(result.profile, out / "profile.yaml"),
        out / "report.json",
        out / "report.md",
        out / "joints.png",
    ]
    paths[1].write_text(json.dumps(data, indent=2) + "\n")
    paths[2].write_text(_markdown(data))
    _plot(result, joint_names, paths[3])
    return paths


__all__ = ["summary", "write_report"]

#!/usr/bin/env python3
"""Summarises `mcflow run-seq` output folders, one row each: how the pairs started, time per pair, id persistence.

Usage: scripts/sequence_stats.py OUT_DIR [OUT_DIR ...]

Reads OUT_DIR/sequence.json (per pair: start kind, solve time, ids) and OUT_DIR/trajectories.csv (per pair and
segment: support in pixels). Needs no ground truth, so it works for any bag or folder:
  - ms/pair: mean and median solve time (Result timings, total) of the pairs after the first: the first pair of a
    sequence is cold in both modes and is left out, as mcflow_bench_stream does;
  - kept: of the labelled pixels of each pair after the first, the fraction whose segment id was also an id of the
    previous pair (support-weighted, averaged over pairs): 1.0 when no pixel changes to a new id;
  - new ids: ids first seen after pair 0, per pair; distinct: ids over the whole run;
  - bg changes: how often the id of the largest segment (the background in the synthetic scenes) changes;
  - segments: per pair, the share of pairs with one segment, the median and the largest count, and the mean count
    of the last third of the pairs against the first third (drift: a stream that accumulates segments grows);
  - rmseI / rmseZ: the mean over pairs of how well each pair's flow explains frame 2 (run-seq's residuals: frame 2
    warped back, intensity in [0, 1] and depth in mm, every pixel with depth that stays in view).
With ground truth (OUT_DIR/pair_NNNN/eval.json from `mcflow eval --result OUT_DIR/pair_NNNN --gt GT/pair_NNNN`, e.g.
GT = `mcflow synth --frames N --no-events` for the demo bag), also mcflow_bench_stream's measures:
  - EPE: mean optical-flow end-point error [px] over all pairs (non-occluded pixels);
  - id_keep: of the consecutive pairs in which a true part of at least 200 px has a majority id in both, the
    fraction in which that id stays the same.
"""
import csv
import json
import os
import statistics
import sys


def summarise(folder):
    with open(os.path.join(folder, "sequence.json")) as f:
        pairs = json.load(f)
    support = {}  # pair -> {id: support}
    with open(os.path.join(folder, "trajectories.csv")) as f:
        for row in csv.DictReader(f):
            support.setdefault(int(row["pair"]), {})[int(row["id"])] = float(row["support"])
    starts = [p["start"] for p in pairs]
    later = [p["total_ms"] for p in pairs[1:]]
    kept, new_ids = [], 0
    seen = set(pairs[0]["ids"]) if pairs else set()
    background = []
    for k, p in enumerate(pairs):
        s = support.get(p["pair"], {})
        if s:
            background.append(max(s, key=s.get))
        if k == 0:
            continue
        previous = set(pairs[k - 1]["ids"])
        total = sum(s.values())
        if total > 0:
            kept.append(sum(v for i, v in s.items() if i in previous) / total)
        new_ids += len(set(p["ids"]) - seen)
        seen |= set(p["ids"])
    epe, kept_parts, judged = [], 0, 0
    previous_ids = None
    for p in pairs:
        path = os.path.join(folder, "pair_%04d" % p["pair"], "eval.json")
        if not os.path.exists(path):
            epe, previous_ids = None, None
            break
        with open(path) as f:
            e = json.load(f)
        epe.append(e["optical_flow_epe_px"])
        ids = {q["part"]: q["majority_id"] for q in e["part_ids"] if q["pixels"] >= 200 and q["majority_id"] > 0}
        if previous_ids is not None:
            for part, i in ids.items():
                if part in previous_ids:
                    judged += 1
                    kept_parts += previous_ids[part] == i
        previous_ids = ids
    counts = [len(p["ids"]) for p in pairs]
    residuals = [(p["rmse_intensity"], p["rmse_depth_m"]) for p in pairs if "rmse_intensity" in p]
    third = max(1, len(counts) // 3)
    return {
        "one_segment": sum(1 for c in counts if c == 1) / max(len(counts), 1),
        "segments_median": statistics.median(counts) if counts else float("nan"),
        "segments_max": max(counts) if counts else 0,
        "segments_first": statistics.mean(counts[:third]) if counts else float("nan"),
        "segments_last": statistics.mean(counts[-third:]) if counts else float("nan"),
        "epe": statistics.mean(epe) if epe else None,
        "rmse_i": statistics.mean(r[0] for r in residuals) if residuals else None,
        "rmse_z_mm": 1000 * statistics.mean(r[1] for r in residuals) if residuals else None,
        "id_keep": kept_parts / judged if epe and judged else None,
        "folder": folder,
        "pairs": len(pairs),
        "warm": starts.count("warm"),
        "cold": starts.count("cold"),
        "fallbacks": starts.count("cold_fallback"),
        "ms_mean": statistics.mean(later) if later else float("nan"),
        "ms_median": statistics.median(later) if later else float("nan"),
        "kept": statistics.mean(kept) if kept else float("nan"),
        "new_per_pair": new_ids / max(len(pairs) - 1, 1),
        "distinct": len(seen),
        "bg_changes": sum(1 for a, b in zip(background, background[1:]) if a != b),
    }


def main(argv):
    if len(argv) < 2 or argv[1] in ("-h", "--help"):
        print(__doc__.strip())
        return 0 if len(argv) >= 2 else 2
    print("| run | pairs | warm / cold / fallbacks | ms/pair mean (median), pairs 2.. | kept | new ids/pair | distinct ids "
          "| bg changes | segments: 1-seg share, median, max, first -> last third | rmseI / rmseZ mm | EPE px | id_keep |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for folder in argv[1:]:
        try:
            r = summarise(folder)
        except (OSError, ValueError, KeyError) as e:
            print("sequence_stats.py: %s: %s" % (folder, e), file=sys.stderr)
            return 1
        truth = lambda v, f: "-" if v is None else f % v  # noqa: E731 (no eval.json: no ground truth)
        residual = "-" if r["rmse_i"] is None else "%.4f / %.2f" % (r["rmse_i"], r["rmse_z_mm"])
        print("| %s | %d | %d / %d / %d | %.1f (%.1f) | %.3f | %.2f | %d | %d | %.2f, %g, %d, %.1f -> %.1f | %s | %s | %s |" % (
            r["folder"], r["pairs"], r["warm"], r["cold"], r["fallbacks"], r["ms_mean"], r["ms_median"], r["kept"],
            r["new_per_pair"], r["distinct"], r["bg_changes"], r["one_segment"], r["segments_median"],
            r["segments_max"], r["segments_first"], r["segments_last"], residual, truth(r["epe"], "%.4f"),
            truth(r["id_keep"], "%.3f")))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

"""The revised transfer method against the previous reading, on the same runs (issue 11).

A reduced-size reproduction of Fig. 7, 9 and 11, once with the learner's defaults ("new") and
once with the previous reading's settings ("old": baseline = the prior's feature space without
transfer, positives-only sources, normalised relatedness with eps_neg 0.4, every model in the
prior's feature space, plain ML-II). Both readings are options of the learner, so the runs
differ by the method alone (same data, groups, pool orders, exploration draws).

    python benches/transfer_readings.py OUT new|old DATA.h5 [--repetitions 20] [--cutoff paper]

DATA.h5: a data set of all 15 objects and 7 actions (``aptkt dataset generate -n 20``). The
numbers in docs/experiments.md ("The method's choices, measured" and "The evidence cut-off")
come from this script. ``--cutoff paper`` runs the "new" reading with Eq. 3's ε_neg alone instead
of the evidence test (LearnerConfig.cutoff); ``--feature-space`` sets
LearnerConfig.feature_space of the transferring methods (with ``evidence``, APTKT-multi keeps
``auto``: the evidence choice needs one source per classifier). ``--class-prior uniform``
combines every model's one-vs-all probabilities (the baseline's too) under equal class
frequencies (GPSettings.class_prior).
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path


def main() -> None:
    import aptkt.experiments.figures.base as base
    import aptkt.experiments.reproduce as rep
    from aptkt.experiments.scale import Scale
    from aptkt.learning import GPSettings

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("output", type=Path)
    p.add_argument("reading", choices=("new", "old"))
    p.add_argument("data", type=Path)
    p.add_argument("--repetitions", type=int, default=20)
    p.add_argument("--figures", default="fig7,fig9,fig11")
    p.add_argument("-j", "--jobs", type=int, default=2)
    p.add_argument("--cutoff", choices=("evidence", "paper"), default=None)
    p.add_argument("--evidence-margin", default=None, help="a number, or 'lnN' (None)")
    p.add_argument("--fig11-trials", type=int, default=3)
    p.add_argument(
        "--feature-space",
        choices=("auto", "covered", "prior", "new", "pooled", "evidence"),
        default=None,
    )
    p.add_argument(
        "--class-prior",
        choices=("training", "uniform"),
        default=None,
        help="how every model (baseline included) combines its one-vs-all probabilities",
    )
    args = p.parse_args()
    scale = Scale.full().with_(
        name="mid",
        repetitions=args.repetitions,
        budget=10,
        groups=3,
        trials=2,
        prior_counts=(3, 10),
        fig11_trials=args.fig11_trials,
    )
    if args.cutoff is not None or args.evidence_margin is not None or args.feature_space:
        over: dict = {} if args.cutoff is None else {"cutoff": args.cutoff}
        if args.feature_space is not None:
            over["feature_space"] = args.feature_space
        if args.evidence_margin is not None:
            m = args.evidence_margin
            over["evidence_margin"] = None if m == "lnN" else float(m)
        methods = dict(base.METHODS)
        for k, v in methods.items():
            # The stress test without a cut-off stays without one.
            if v.get("transfer") in ("paper", "multi") and k != base.STRESS_NO_CUTOFF:
                methods[k] = {**v, **over}
                if v.get("transfer") == "multi" and over.get("feature_space") == "evidence":
                    # The evidence choice needs one source per classifier: "multi" keeps "auto".
                    methods[k].pop("feature_space")
        base.METHODS = methods
    gp = GPSettings()
    if args.reading == "old":
        scale = scale.with_(eps_neg=0.4)
        old = {
            "source": "positives",
            "relatedness": "normalised",
            "feature_space": "prior",
            "cutoff": "paper",
        }
        methods = dict(base.METHODS)
        methods["baseline"] = {"transfer": "control"}
        for k in ("APTKT", "APTKT+aux", "APTKT-multi", base.STRESS_CUTOFF, base.STRESS_NO_CUTOFF):
            methods[k] = {**methods[k], **old}
        base.METHODS = methods
        gp = GPSettings(hyper_prior=None)
    if args.class_prior is not None:
        gp = replace(gp, class_prior=args.class_prior)
    rep.reproduce(
        rep.ReproduceSettings(
            figures=tuple(args.figures.split(",")),
            output=args.output,
            data=args.data,
            jobs=args.jobs,
            scale=scale,
            gp=gp,
            progress=False,
            command=f"benches/transfer_readings.py {args.output} {args.reading} {args.data}",
        )
    )


if __name__ == "__main__":
    main()

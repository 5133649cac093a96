"""A study on a SLURM cluster through dask-jobqueue: one GPU per worker job, each launch a task that needs it.

Written for the README's cluster section and checked to compile (tests/study/test_cluster.py); not run here,
where there is no SLURM. Adjust the queue, account and resources to the site's.

    pip install dask-jobqueue
    python docs/cluster/slurm_study.py studies/pellets_bbd.toml 4
"""

import sys

from dask_jobqueue import SLURMCluster

from warpdem import run_study


def main(study: str, gpus: int) -> None:
    cluster = SLURMCluster(
        queue="gpu",
        account="my-project",
        cores=8,  # CPU cores of one job (one worker process, one thread: Warp launches one kernel stream)
        processes=1,
        memory="64GB",
        walltime="04:00:00",
        job_extra_directives=["--gres=gpu:1"],
        worker_extra_args=["--resources", "GPU=1", "--nthreads", "1"],
        job_script_prologue=["module load cuda"],
    )
    cluster.scale(jobs=gpus)
    try:
        print(f"dashboard: {cluster.dashboard_link}")
        # each finished launch is written under runs/ here as it arrives; rerunning resumes
        res = run_study(study, device="cuda", scheduler=cluster.scheduler_address)
        print(f"{res['ran']} runs in {res['wall_s']:.0f} s")
    finally:
        cluster.close()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 2)

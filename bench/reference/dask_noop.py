#!/usr/bin/python3
"""Dask reference for the dispatch benchmark: a LocalCluster of N single-threaded worker processes
runs T no-op tasks (client.map + gather); prints tasks per second. Debian's python3-distributed."""
import argparse
import time


def noop(x):
    return x


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--tasks", type=int, default=5000)
    args = parser.parse_args()
    import dask
    from distributed import Client, LocalCluster
    dask.config.set({"distributed.worker.daemon": False, "logging.distributed": "error"})
    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        client.gather(client.map(noop, range(100), pure=False))  # warm up
        start = time.perf_counter()
        futures = client.map(noop, range(args.tasks), pure=False)
        client.gather(futures)
        seconds = time.perf_counter() - start
    print(f"{args.tasks / seconds:.1f}")


if __name__ == "__main__":
    main()

#!/usr/bin/env bash
# The measurements of results/mpi_scaling.md, on loopback:
#   scripts/mpi_scaling.sh bytes BUILD OUT   bytes exchanged a pass and a frame (car, texture-
#                                            space path at the hits) by resolution and ranks
#   scripts/mpi_scaling.sh pingpong BUILD    latency and bandwidth between two ranks
#   scripts/mpi_scaling.sh ab BUILD N        2 ranks x 1 thread (texcache's wait, and MPI's
#                                            polling) against 1 rank x 2 threads, alternating,
#                                            N runs each: medians of render, CPU, job seconds
#   scripts/mpi_scaling.sh model OUT_PREFIX CORE_SECONDS U F
#                                            the scaling model of a pass (results/mpi_scaling.md):
#                                            CORE_SECONDS of compute a pass, U bytes of bins in
#                                            all, F bytes each rank sends whatever its share
set -euo pipefail
what="$1" build="${2:-}"
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
[ "$(id -u)" -ne 0 ] || export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_btl_vader_single_copy_mechanism=none  # containers forbid its ptrace copies
mpi=(mpirun --oversubscribe)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
scene="$root/scenes/car.json"
opts=(--spp 4 --pass-spp 4 --shading texture --integrator path -q --no-png --seed 1)

case "$what" in
bytes)
    out="$3"
    echo "resolution,ranks,passes,pass_bytes,bytes_sent,bytes_received,seconds,cpu_seconds" >"$out"
    for res in ${RESOLUTIONS:-240x135 480x270 960x540}; do
        for np in ${RANKS:-2 3}; do
            "${mpi[@]}" -np "$np" "$build/bin/texcache" render "$scene" --resolution "$res" \
                "${opts[@]}" -o "$tmp/i.exr" --stats "$tmp/s.json" >/dev/null
            get() { sed -n "s/.*\"$1\": \([0-9.e+-]*\).*/\1/p" "$tmp/s.json"; }
            echo "$res,$np,$(get passes),$(get pass_bytes),$(get bytes_sent),$(get bytes_received),$(get seconds),$(get cpu_seconds)" |
                tee -a "$out"
        done
    done
    ;;
pingpong) "${mpi[@]}" -np 2 "$build/bin/mpi_pingpong" ;;
ab)
    # Three ways alternating, so that the other load on the machine falls on all alike: 2 ranks
    # x 1 thread waiting as texcache does (a sleeping barrier before each collective), the same
    # waiting as MPI does (TEXCACHE_MPI_WAIT=poll), and 1 rank x 2 threads. Each run's render
    # seconds (rank 0's wall clock), render CPU seconds (all ranks) and the whole job's wall
    # seconds (start-up, scene load and BVH build included, done by every rank).
    n="$3"
    run() {  # name env... -- command...
        local name="$1" t0 t1 line
        shift
        t0="$(date +%s.%N)"
        line="$(env "$@" --stats "$tmp/s.json" | sed -n 's/^time: \([0-9.]*\) s render.*/\1/p')"
        t1="$(date +%s.%N)"
        local cpu
        cpu="$(sed -n 's/.*"cpu_seconds": \([0-9.e+-]*\).*/\1/p' "$tmp/s.json")"
        echo "$name $line $cpu $(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.3f", b-a}')" >>"$tmp/ab"
        printf '%s: render %s s, CPU %s s, job %s s; ' "$name" "$line" "$cpu" \
            "$(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.3f", b-a}')"
    }
    r=(render "$scene" --resolution 480x270 "${opts[@]}")
    for i in $(seq "$n"); do
        printf 'run %s: ' "$i"
        run ranks TEXCACHE_MPI_WAIT=sleep "${mpi[@]}" -np 2 "$build/bin/texcache" "${r[@]}" \
            --threads 1 -o "$tmp/a.exr"
        run ranks-poll TEXCACHE_MPI_WAIT=poll "${mpi[@]}" -x TEXCACHE_MPI_WAIT -np 2 \
            "$build/bin/texcache" "${r[@]}" --threads 1 -o "$tmp/a.exr"
        run threads TEXCACHE_MPI_WAIT=sleep "$build/bin/texcache" "${r[@]}" --threads 2 \
            -o "$tmp/b.exr"
        echo
    done
    median() {  # name column
        awk -v n="$1" -v c="$2" '$1 == n { print $c }' "$tmp/ab" | sort -g |
            awk '{v[NR]=$1} END {print (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2)}'
    }
    for col in 2:render 3:cpu 4:job; do
        c="${col%%:*}" what="${col#*:}"
        a="$(median ranks "$c")" p="$(median ranks-poll "$c")" b="$(median threads "$c")"
        echo "median $what seconds: 2 ranks x 1 thread $a (MPI's polling: $p), 1 rank x 2 threads $b; ratio $(awk -v a="$a" -v b="$b" 'BEGIN{printf "%.3f", a/b}') (polling: $(awk -v a="$p" -v b="$b" 'BEGIN{printf "%.3f", a/b}'))"
    done
    echo "load average: $(cut -d' ' -f1-3 /proc/loadavg)"
    ;;
model)
    # A rank is a node of 32 cores as fast as this machine's; two interconnects (latency alpha,
    # bandwidth beta): InfiniBand HDR (2 us, 12 GB/s) and 10 Gb Ethernet (30 us, 1.1 GB/s).
    # A rank's bins of a pass: S(N) = U/N + F. Allgather (today's exchange): each rank
    # receives the others' bins, (N-1) S(N) bytes, over a ring of N-1 steps. Partitioned
    # (bins summed at a home rank by key, each rank fetching back those its hits read):
    # 2 S(N) bytes and 2 (N-1) messages, of which only ~min(N-1, 64) carry bins.
    out="$2" core="$3" u="$4" f="$5"
    awk -v core="$core" -v u="$u" -v f="$f" 'BEGIN {
        print "ranks,compute,allgather_ib,partitioned_ib,allgather_eth,partitioned_eth";
        for (n = 1; n <= 4096; n *= 2) {
            s = n > 1 ? u / n + f : 0; c = core / (32 * n);
            m = n - 1 < 64 ? n - 1 : 64;  # one rank alone exchanges nothing
            printf "%d,%g,%g,%g,%g,%g\n", n, c,
                c + (n - 1) * 2e-6 + (n - 1) * s / 12e9, c + 2 * m * 2e-6 + 2 * s / 12e9,
                c + (n - 1) * 30e-6 + (n - 1) * s / 1.1e9, c + 2 * m * 30e-6 + 2 * s / 1.1e9;
        }
    }' >"$out.csv"
    cat "$out.csv"
    gnuplot <<GP
set terminal pngcairo size 800,500
set output "$out.png"
set datafile separator ","
set logscale xy
set key top right
set grid
set title "3840x2160, one pass of 1 spp (car, path, texture space at the hits): model"
set xlabel "ranks (nodes of 32 cores)"
set ylabel "seconds a pass"
plot "$out.csv" using 1:2 with linespoints title "compute only", \
     "" using 1:3 with linespoints title "allgather, InfiniBand", \
     "" using 1:4 with linespoints title "partitioned, InfiniBand", \
     "" using 1:5 with linespoints title "allgather, 10 GbE", \
     "" using 1:6 with linespoints title "partitioned, 10 GbE"
GP
    ;;
*) echo "mpi_scaling.sh: error: unknown measurement '$what'" >&2; exit 2 ;;
esac

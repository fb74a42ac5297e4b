// SPDX-License-Identifier: Apache-2.0
// `mpirun -np 2 mpi_pingpong`: the latency and bandwidth between two ranks, the two inputs of the
// scaling model in results/mpi_scaling.md. Rank 0 sends a message of each size to rank 1, which
// sends it back; half the median round trip over the repeats is the one-way time. Prints
// "bytes one_way_us MB_per_s" lines, then the latency (8 bytes) and the bandwidth (largest).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

#include <algorithm>
#include <cstdio>
#include <vector>

int main(int argc, char** argv) {
    MPI_Init(&argc, &argv);
    int rank = 0, size = 1;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
    if (size != 2) {
        if (rank == 0) std::fprintf(stderr, "mpi_pingpong: error: run it on 2 ranks\n");
        MPI_Finalize();
        return 2;
    }
    std::vector<char> buf(size_t(64) << 20);
    double latency = 0.0, bandwidth = 0.0;
    for (size_t bytes = 8; bytes <= buf.size(); bytes *= 8) {
        const int repeats = bytes < (size_t(1) << 20) ? 200 : 10;
        std::vector<double> times;
        for (int i = 0; i < repeats + 2; ++i) {  // two untimed round trips first
            MPI_Barrier(MPI_COMM_WORLD);
            const double t0 = MPI_Wtime();
            if (rank == 0) {
                MPI_Send(buf.data(), int(bytes), MPI_BYTE, 1, 0, MPI_COMM_WORLD);
                MPI_Recv(buf.data(), int(bytes), MPI_BYTE, 1, 0, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            } else {
                MPI_Recv(buf.data(), int(bytes), MPI_BYTE, 0, 0, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
                MPI_Send(buf.data(), int(bytes), MPI_BYTE, 0, 0, MPI_COMM_WORLD);
            }
            if (i >= 2) times.push_back((MPI_Wtime() - t0) / 2.0);
        }
        std::nth_element(times.begin(), times.begin() + times.size() / 2, times.end());
        const double oneWay = times[times.size() / 2];
        if (rank == 0) std::printf("%zu %.3f %.1f\n", bytes, oneWay * 1e6, bytes / oneWay * 1e-6);
        if (bytes == 8) latency = oneWay;
        bandwidth = bytes / oneWay;
    }
    if (rank == 0)
        std::printf("latency %.2f us, bandwidth %.0f MB/s\n", latency * 1e6, bandwidth * 1e-6);
    MPI_Finalize();
    return 0;
}

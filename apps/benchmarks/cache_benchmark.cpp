// SPDX-License-Identifier: Apache-2.0
// Google Benchmark of the cache's hot path: a texel-cache hit (eq. 1 + eq. 2 + hash + seqlock
// read) on one thread, and two threads hammering the same region. Compare the per-lookup times of
// the 1- and 2-thread runs printed side by side (same process, same binary).
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "testing/cages.h"
#include "texcache/shading_cache.h"

namespace {

using namespace texcache;

struct Sample {
    float v[4];
};

// One cache shared by all benchmark threads, warmed with a 64x64-texel region.
struct Fixture {
    ShadingCache<Sample, float> cache{CacheSettings{}};
    std::vector<CacheHit> hits;
    Fixture() {
        const int mesh =
            cache.AddMesh(test::GridCage(4), 1.0f / 256.0f);  // 256 texels a face at mip 0
        for (int i = 0; i < 4096; ++i) {
            const float u = (float(i % 64) + 0.5f) / 256.0f, v = (float(i / 64) + 0.5f) / 256.0f;
            hits.push_back({mesh, 5, u, v, 1.0f / 256.0f, 0.0f, 0.0f, 1.0f / 256.0f});
        }
        CacheStats st;
        for (const CacheHit& h : hits) cache.Lookup(h, 0, Shade, Centre, st);
    }
    static Sample Shade(const SampleRequest& r) { return {{r.u, r.v, 0, 0}}; }
    static float Centre(const FilterInput<Sample>& in) { return in.samples[in.centre].v[0]; }
};
Fixture& Shared() {
    static Fixture f;
    return f;
}

void BM_TexelCacheHit(benchmark::State& state) {
    Fixture& f = Shared();
    CacheStats st;
    size_t i = size_t(state.thread_index()) * 977;
    float sink = 0.0f;
    for (auto _ : state) {
        sink += f.cache.Lookup(f.hits[i & 4095], 0, Fixture::Shade, Fixture::Centre, st);
        i += 7;
    }
    benchmark::DoNotOptimize(sink);
    if (st.texelHits != st.lookups) state.SkipWithError("lookups missed the warm cache");
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_TexelCacheHit)->Threads(1)->Threads(2)->UseRealTime();

// The same loop without the cache (eq. 1 + eq. 2 only): what addressing alone costs.
void BM_AddressingOnly(benchmark::State& state) {
    Fixture& f = Shared();
    size_t i = 0;
    uint64_t sink = 0;
    for (auto _ : state) {
        sink += f.cache.TexelAt(f.hits[i & 4095]).key.Pack();
        i += 7;
    }
    benchmark::DoNotOptimize(sink);
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_AddressingOnly);

}  // namespace

BENCHMARK_MAIN();

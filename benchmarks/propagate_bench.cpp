// Stand-alone timing of the propagation kernels (no Python), for a quiet
// machine: reads records written by `benchmarks/propagation.py dump`, times
// one gathering pass over all families (the one-pass walk and the sorted
// reference walk) and the shooting, on the thread counts given.
//
//   g++ -O3 -std=c++17 -pthread -Icsrc benchmarks/propagate_bench.cpp csrc/lineframe.cpp \
//       csrc/linesystem.cpp csrc/gather.cpp csrc/pairtable.cpp csrc/shoot.cpp \
//       csrc/reference.cpp csrc/util/memory.cpp -o bench
//   ./bench records.bin 1 2
//   ./bench records.bin stride=10 1    (every 10th gathering family: a quick A/B of two
//                                        builds of the kernels, side by side)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <vector>

#include "linesystem.h"

template <class T>
static std::vector<T> read_vec(std::ifstream& f, int64_t n) {
    std::vector<T> v(n);
    f.read(reinterpret_cast<char*>(v.data()), sizeof(T) * n);
    return v;
}

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: %s records.bin [threads...]\n", argv[0]);
        return 2;
    }
    std::ifstream f(argv[1], std::ios::binary);
    int64_t n, ne, nfg, nfs;
    f.read(reinterpret_cast<char*>(&n), 8);
    auto ijk = read_vec<int32_t>(f, 3 * n);
    auto nrm = read_vec<float>(f, 3 * n);
    auto pt = read_vec<float>(f, 3 * n);
    auto val = read_vec<float>(f, 3 * n);
    f.read(reinterpret_cast<char*>(&ne), 8);
    auto emit = read_vec<int32_t>(f, ne);
    std::vector<voxgi::Family> fams[2];
    for (int k = 0; k < 2; ++k) {
        int64_t nf;
        f.read(reinterpret_cast<char*>(&nf), 8);
        auto v = read_vec<int32_t>(f, 3 * nf);
        auto w = read_vec<double>(f, nf);
        fams[k].resize(nf);
        for (int64_t i = 0; i < nf; ++i) {
            for (int c = 0; c < 3; ++c) fams[k][i].v[c] = v[3 * i + c];
            fams[k][i].weight = w[i];
        }
    }
    nfg = fams[0].size();
    nfs = fams[1].size();
    if (!f) {
        std::fprintf(stderr, "short read\n");
        return 1;
    }
    std::vector<int> threads;
    int64_t stride = 1;
    for (int i = 2; i < argc; ++i) {
        if (std::strncmp(argv[i], "stride=", 7) == 0)
            stride = std::max<int64_t>(1, std::atoll(argv[i] + 7));
        else
            threads.push_back(std::atoi(argv[i]));
    }
    if (threads.empty()) threads = {1, 2};

    voxgi::LineSystem sys(n, ijk.data(), nrm.data(), pt.data(), 0.02f, 16);
    std::vector<int64_t> sel;
    for (int64_t i = 0; i < nfg; i += stride) sel.push_back(i);
    std::vector<double> out(3 * n), hd(3 * n), unf(ne);
    voxgi::StopCheck none;
    auto now = [] { return std::chrono::steady_clock::now(); };
    auto secs = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
    std::printf(
        "records %lld  emitters %lld  gather families %lld (of %lld)  shoot families %lld\n",
        (long long)n, (long long)ne, (long long)sel.size(), (long long)nfg, (long long)nfs);
    std::printf("%8s %10s %10s %12s %14s\n", "threads", "kernel", "seconds", "Mrays/s",
                "Mrays/s/thread");
    for (int th : threads) {
        for (int onepass = 1; onepass >= 0; --onepass) {
            voxgi::GatherOptions opt;
            opt.threads = th;
            auto pass = [&](int64_t nsel) {
                if (onepass)
                    sys.gather(fams[0].data(), sel.data(), nsel, val.data(), out.data(), nullptr,
                               opt, none);
                else
                    sys.gather_sorted(fams[0].data(), sel.data(), nsel, val.data(), out.data(),
                                      nullptr, false, opt, none);
            };
            pass(std::min<int64_t>(16, sel.size()));  // warm-up
            double best = 1e30;
            for (int r = 0; r < 2; ++r) {
                auto t0 = now();
                pass(static_cast<int64_t>(sel.size()));
                best = std::min(best, secs(t0, now()));
            }
            const double rays = double(n) * sel.size();
            std::printf("%8d %10s %10.3f %12.1f %14.1f\n", th, onepass ? "onepass" : "sort", best,
                        rays / best / 1e6, rays / best / 1e6 / th);
        }
        voxgi::ShootOptions opt;
        opt.threads = th;
        auto t0 = now();
        const voxgi::ShootCount count = sys.shoot(emit.data(), ne, fams[1].data(), nfs, val.data(),
                                                  hd.data(), unf.data(), opt, none);
        const double s = secs(t0, now());
        const int64_t rays = count.rays, steps = count.steps;
        std::printf(
            "%8d %10s %10.3f %12.1f %14.1f   (%lld rays, %lld voxel steps, %.1f Msteps/s)\n", th,
            "shoot", s, rays / s / 1e6, rays / s / 1e6 / th, (long long)rays, (long long)steps,
            steps / s / 1e6);
    }
    return 0;
}

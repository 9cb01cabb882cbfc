#include "imaging/box_filter.h"

#include <cmath>
#include <cstddef>
#include <cstring>

namespace sonotrace::imaging {

int box3_radius(double sigma) {
    int b = int(std::lround(std::sqrt(4.0 * sigma * sigma + 1.0)));
    b += 1 - b % 2;
    return b / 2;
}

[[gnu::target_clones("avx2", "default")]] const Moments* smooth_box3(Moments* v, Moments* scratch,
                                                                     int n, int r) {
    // A sample's moments as one vector (GCC vector extensions: one AVX register, or two
    // SSE2 ones); left to itself GCC kept the four channels scalar.
    typedef double v4d __attribute__((vector_size(32)));
    static_assert(sizeof(v4d) == sizeof(Moments));
    const double inverse_b = 1.0 / double(2 * r + 1);  // a multiply per sample, not a division
    Moments *in = v + r, *out = scratch + r;
    for (int pass = 0; pass < 3 && r > 0; ++pass) {
        v4d sum = {0.0, 0.0, 0.0, 0.0}, entering, leaving;
        for (int i = 0; i < r; ++i) {  // the window of sample 0 but its entering sample r
            std::memcpy(&entering, &in[i], sizeof entering);
            sum += entering;
        }
        // The sample entering and the one leaving are combined first, so the running sum
        // waits for one add per sample, not two.
        for (int i = 0; i < n; ++i) {
            std::memcpy(&entering, &in[i + r], sizeof entering);
            std::memcpy(&leaving, &in[i - r], sizeof leaving);
            const v4d smoothed = (sum + entering) * inverse_b;
            std::memcpy(&out[i], &smoothed, sizeof smoothed);
            sum += entering - leaving;
        }
        std::swap(in, out);
    }
    return in;
}

}  // namespace sonotrace::imaging

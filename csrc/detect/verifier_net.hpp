// verifier_net.hpp - the verifier CNN's forward pass, written for its one architecture instead of run by cv::dnn.
//
// The network `headway train verifier --out X.onnx` writes (app/train/verifier_onnx.py holds its equations):
//     a1 = maxpool2(relu(conv3x3(z, c1)))   a2 = maxpool2(relu(conv3x3(a1, c2)))   a3 = maxpool2(relu(conv3x3(a2, c3)))
//     h  = relu(W_f flatten(a3) + W_e extra + b_h),   p = sigmoid(w_o . h + b_o),   d = W_d h + b_d (optional)
// with convolutions padded by one pixel and 2x2 pools of stride 2. cv::dnn runs these tiny layers (1 input channel,
// 8-64 output channels, 48 x 32 maps) at a few GMAC/s: an 8/16/32 network, ~1 M multiply-adds a crop, took
// ~0.2 ms a crop, half of a tracked frame's cascade stage (docs/decisions.md). Here each crop's maps
// stay in the cache (a conv computes two rows, pools them and writes the next layer's padded input), and the output
// channels are the SIMD lanes: six output pixels at a time, every input value broadcast once against 8 or 16 output
// channels' weights, with AVX2 + FMA where the CPU has them (runtime dispatch, as haar_cascade.cpp; the objects carry
// no -march), plain loops elsewhere. With AVX2 the layers of 8 or more input channels (the second and third, ~90 % of
// the multiply-adds) are Winograd F(2x2, 3x3) convolutions: 2.25x fewer multiplies, and each 2x2 output tile is one
// pool window (verifier_net.cpp).
//
// The arithmetic is float, as cv::dnn's, in another order of summation: answers agree to ~1e-6 (a test compares both
// on real crops; the verifier compares both paths with cv::dnn when it loads the file and refuses the file, naming
// cascade.verifier_dnn, if they differ by more than 1e-4).
// max-pool and ReLU commute with the bias (all three are monotone), so the bias and ReLU are applied after the pool.
#pragma once

#include <opencv2/dnn.hpp>

#include <memory>
#include <vector>

namespace hw {

class WorkerPool;

class VerifierNet {
public:
    // The network `net` (cv::dnn, read from a verifier ONNX) holds, for crops of crop_h x crop_w; null when it is
    // not of the form above (another graph, a crop height not a multiple of 8 or width of 24, channel counts not
    // multiples of 8).
    static std::unique_ptr<VerifierNet> from_dnn(cv::dnn::Net &net, int crop_h, int crop_w);

    bool has_box() const { return !box_w_.empty(); }
    // n standardised crops (n x crop_h x crop_w floats, one after the other) and their extra features (n x 2): the
    // probabilities p[n] and, when `box` is given and the network has the box output, its offsets (n x 4).
    // Shared among the threads of set_pool()'s pool (base/worker_pool.hpp), four crops a piece: every crop's
    // outputs are what one thread gives.
    void forward(const float *crops, const float *extra, int n, float *p, float *box) const;
    void set_pool(WorkerPool *pool) { pool_ = pool; }  // null: the calling thread alone
    // the same in plain loops, direct convolutions (the path of CPUs without AVX2; CnnVerifier's load check compares
    // it with cv::dnn on every CPU)
    void forward_plain(const float *crops, const float *extra, int n, float *p, float *box) const;

private:
    WorkerPool *pool_ = nullptr;  // not owned
    struct Conv {
        int cin = 0, cout = 0;
        std::vector<float> w;  // [ky][kx][cin][cout]: the output channels contiguous (the SIMD lanes)
        std::vector<float> b;  // [cout]
        std::vector<float> wino;  // [16][cin][cout]: G g G^T (Winograd F(2x2, 3x3)); empty unless cin % 8 and cout % 16 are 0
    };
    void run(const float *crops, const float *extra, int n, float *p, float *box, bool avx2) const;

    int h_ = 0, w_ = 0;      // crop size
    Conv conv_[3];
    int hidden_ = 0;
    std::vector<float> dense_w_;  // [input][hidden]: the flattened a3 in (row, column, channel) order, then the 2 extra
    std::vector<float> dense_b_;  // [hidden]
    std::vector<float> out_w_;    // [hidden]
    float out_b_ = 0.f;
    std::vector<float> box_w_;    // [4][hidden]; empty without the box output
    std::vector<float> box_b_;    // [4]
    bool avx2_ = false;
};

} // namespace hw

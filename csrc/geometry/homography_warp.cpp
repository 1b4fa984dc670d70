#include "geometry/homography_warp.hpp"

#include <opencv2/imgproc.hpp>

namespace hw {

void warp_homography(const cv::Mat &src, const cv::Matx33d &H, cv::Size size, cv::Mat &dst) {
    const cv::Matx33d Hi = H.inv();
    cv::Mat mx(size, CV_32FC1), my(size, CV_32FC1);
    const float a = float(Hi(0, 0)), c = float(Hi(1, 0)), e = float(Hi(2, 0));
    for (int y = 0; y < size.height; ++y) {
        // Per row, the numerators and the denominator are affine in x.
        const float b = float(Hi(0, 1) * y + Hi(0, 2)), d = float(Hi(1, 1) * y + Hi(1, 2)), f = float(Hi(2, 1) * y + Hi(2, 2));
        float *px = mx.ptr<float>(y), *py = my.ptr<float>(y);
        for (int x = 0; x < size.width; ++x) {
            const float xf = float(x), w = 1.f / (e * xf + f);
            px[x] = (a * xf + b) * w;
            py[x] = (c * xf + d) * w;
        }
    }
    cv::remap(src, dst, mx, my, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
}

} // namespace hw

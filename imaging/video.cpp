#include "imaging/video.h"

#include <malloc.h>

#include <cstdlib>

#include <opencv2/imgproc.hpp>

#include "tissue/base/error.h"

namespace sonotrace::imaging {

namespace {

// The encoder (x264 through FFmpeg and OpenCV) reads memory it never wrote: on a heap
// that earlier work left dirty, the same frames gave different bitstreams (a resumed
// sweep's video differed from an uninterrupted one's). While a clip is opened, written
// and closed, glibc fills every new allocation with one byte, so the clip is a function
// of its frames alone.
struct DeterministicHeap {
    DeterministicHeap() { mallopt(M_PERTURB, 0x5a); }
    ~DeterministicHeap() { mallopt(M_PERTURB, 0); }
    DeterministicHeap(const DeterministicHeap&) = delete;
    DeterministicHeap& operator=(const DeterministicHeap&) = delete;
};

}  // namespace

VideoClip::VideoClip(const std::string& path, const std::string& container, double fps,
                     cv::Size size, const std::string& shown_as)
    : size_(size.width & ~1, size.height & ~1) {
    const std::string& name = shown_as.empty() ? path : shown_as;
    if (container != "mp4" && container != "avi")
        throw base::InputError(name, "", "a clip is mp4 or avi, not '" + container + "'");
    if (size_.width < 2 || size_.height < 2)
        throw base::InputError(name, "", "a clip's frames need at least 2 x 2 pixels");
    const DeterministicHeap heap;
    auto open = [&](char a, char b, char c, char d) {
        return writer_.open(path, cv::CAP_FFMPEG, cv::VideoWriter::fourcc(a, b, c, d), fps, size_,
                            true);
    };
    if (container == "avi") {
        if (open('M', 'J', 'P', 'G')) codec_ = "Motion JPEG";
    } else if (!std::getenv("SONOTRACE_NO_H264") && open('a', 'v', 'c', '1')) {
        codec_ = "H.264";
    } else if (open('m', 'p', '4', 'v')) {
        codec_ = "MPEG-4 Part 2";
        note_ =
            "FFmpeg here has no H.264 encoder (Debian's libavcodec with libx264 has one): the "
            "clip is MPEG-4 Part 2, which browsers may refuse to play";
    }
    if (codec_.empty())
        throw base::InputError(name, "",
                               "OpenCV's FFmpeg backend cannot write " + container + " here");
}

void VideoClip::write(const cv::Mat& frame) {
    cv::Mat bgr;
    if (frame.channels() == 1)
        cv::cvtColor(frame, bgr, cv::COLOR_GRAY2BGR);
    else
        bgr = frame;
    const DeterministicHeap heap;
    writer_.write(bgr(cv::Rect(0, 0, size_.width, size_.height)));
    ++frames_;
}

void VideoClip::close() {
    const DeterministicHeap heap;
    writer_.release();
}

}  // namespace sonotrace::imaging

#pragma once
// Clips of B-mode frames for people: H.264 in MP4 (what browsers and presentation
// software play) through OpenCV's FFmpeg backend, or Motion JPEG in AVI. Where Debian's
// FFmpeg has no H.264 encoder, MP4 falls back to MPEG-4 Part 2 and says so (with the
// environment variable SONOTRACE_NO_H264 set, H.264 is not tried: the machine without the
// encoder, for the test of the fallback).
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

namespace sonotrace::imaging {

class VideoClip {
  public:
    // Opens `path` for frames of `size` (pixels; an odd width or height loses its last
    // column or row: H.264's 4:2:0 needs even ones) at `fps`. `container` is "mp4" or
    // "avi". Throws base::InputError naming `shown_as` (the final name of a staged file;
    // default `path`) if no encoder opens.
    VideoClip(const std::string& path, const std::string& container, double fps, cv::Size size,
              const std::string& shown_as = "");
    // One frame: 8-bit grey or BGR of the size given (cropped to the even size).
    void write(const cv::Mat& frame);
    // Finishes the file (the MP4's index is written here).
    void close();
    // "H.264", "MPEG-4 Part 2" or "Motion JPEG".
    const std::string& codec() const { return codec_; }
    // Empty, or why the clip is not H.264 though MP4 was asked for.
    const std::string& note() const { return note_; }
    cv::Size size() const { return size_; }
    int frames() const { return frames_; }

  private:
    cv::VideoWriter writer_;
    std::string codec_, note_;
    cv::Size size_;
    int frames_ = 0;
};

}  // namespace sonotrace::imaging

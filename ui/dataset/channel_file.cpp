#include "ui/dataset/channel_file.h"

#include <cmath>
#include <limits>
#include <vector>

#include "sonotrace_version.h"
#include "ui/dataset/hdf5_writer.h"

namespace sonotrace::dataset {

std::string channel_file_bytes(const imaging::ChannelData& c, const probe::Transducer& t,
                               const std::string& transmit_text, const std::string& name) {
    hdf5::ImageWriter w(name, 0);
    const hsize_t W = hsize_t(c.transmits), E = hsize_t(c.elements), S = hsize_t(c.samples);
    // A chunk per transmit: a reader takes one transmit at a time without the rest.
    w.dataset(w.file(), "channels", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {W, E, S}, {1, E, S},
              c.values.data(), false);
    std::vector<double> elements, normals;
    for (const probe::ArrayPoint& e : c.element_points) {
        elements.insert(elements.end(), {e.position.x, e.position.y});
        normals.insert(normals.end(), {e.normal.x, e.normal.y});
    }
    w.dataset(w.file(), "elements_mm", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {E, 2}, {},
              elements.data());
    w.dataset(w.file(), "element_normals", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {E, 2}, {},
              normals.data());
    std::vector<uint8_t> kind;
    std::vector<double> angle, source, delays;
    for (int k = 0; k < c.transmits; ++k) {
        const probe::TransmitWave& wave = c.waves[std::size_t(k)];
        const bool diverging = wave.kind == probe::TransmitWave::Kind::diverging;
        kind.push_back(diverging ? 1 : 0);
        angle.push_back(wave.angle_rad);
        const glm::dvec2 v = diverging ? wave.virtual_source()
                                       : glm::dvec2(std::numeric_limits<double>::quiet_NaN());
        source.insert(source.end(), {v.x, v.y});
        delays.insert(delays.end(), c.delays_s[std::size_t(k)].begin(),
                      c.delays_s[std::size_t(k)].end());
    }
    hdf5::Handle g(w.group("transmit"), H5Gclose);
    w.dataset(g, "kind", H5T_STD_U8LE, H5T_NATIVE_UINT8, {W}, {}, kind.data());
    w.dataset(g, "angle_rad", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {W}, {}, angle.data());
    w.dataset(g, "virtual_source_mm", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {W, 2}, {}, source.data());
    w.dataset(g, "delays_s", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {W, E}, {}, delays.data());
    w.attribute("sampling_frequency_hz", c.fs_hz);
    w.attribute("start_time_s", c.start_s);
    w.attribute("speed_of_sound_m_s", c.speed_m_s);
    w.attribute("centre_frequency_hz", c.frequency_hz);
    w.attribute("bandwidth", t.bandwidth);
    w.attribute("pitch_mm", t.pitch_mm);
    w.attribute("element_width_mm", t.element_width_mm);
    w.attribute("probe", t.name);
    w.attribute("transmit", transmit_text);
    w.attribute("time_zero", std::string("a plane wave passes the face's centre (a diverging "
                                         "wave would); sample n is at start_time_s + n / "
                                         "sampling_frequency_hz"));
    w.attribute("version", std::string(SONOTRACE_VERSION));
    return w.image();
}

}  // namespace sonotrace::dataset

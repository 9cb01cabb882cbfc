#pragma once
// Channel data (imaging/channel_data.h) as an HDF5 file, readable with h5py alone, holding
// what another tool needs to beamform it (docs/guide/channel-data.md beamforms one with
// NumPy):
//
//   /channels           float32 [transmits, elements, samples]  each element's RF
//   /elements_mm        float64 [elements, 2]   element centres (x lateral, z depth: 0 on a
//                                               flat array, below 0 along a convex arc)
//   /element_normals    float64 [elements, 2]   each element's unit normal into the tissue
//   /transmit/kind      uint8 [transmits]       0 plane wave, 1 diverging wave
//   /transmit/angle_rad float64 [transmits]     steering angle from the normal (towards +x)
//   /transmit/virtual_source_mm  float64 [transmits, 2]  (x, z) of a diverging wave's
//                                               source behind the face (z < 0); NaN for plane
//   /transmit/delays_s  float64 [transmits, elements]  when each element fires
//   attributes: sampling_frequency_hz, start_time_s (the time of sample 0), speed_of_sound_m_s,
//               centre_frequency_hz, bandwidth (fractional, -6 dB, pulse-echo), pitch_mm,
//               element_width_mm, probe, transmit (the --transmit text), time_zero (what
//               t = 0 is), version
//
// Time zero is the instant a plane wave passes the face's centre, or a diverging wave
// would (the firing times are relative to it: some are negative). Sample n is at
// start_time_s + n / sampling_frequency_hz. Nothing time-dependent is stored: the same
// frame gives the same bytes.
#include <string>

#include "imaging/channel_data.h"
#include "probe/transducer.h"

namespace sonotrace::dataset {

// The file's bytes; throws base::InputError naming `name` if HDF5 fails.
std::string channel_file_bytes(const imaging::ChannelData& channels, const probe::Transducer& t,
                               const std::string& transmit_text, const std::string& name);

}  // namespace sonotrace::dataset

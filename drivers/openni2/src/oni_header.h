// The fixed header at the start of an OpenNI2 .oni file (OpenNI2 1.0.1.0 format, as written by
// openni::Recorder): its stream count, read to diagnose a file OpenNI2 refuses, and completed
// while recording.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>

namespace scanclean::oni {

//! Header bytes: "NI10", version (u8 major, u8 minor, u16 maintenance, u32 build), u64 maximum
//! timestamp, u32 maximum node id; packed, little-endian, 24 bytes.
inline constexpr std::size_t kHeaderSize = 24;
inline constexpr std::size_t kMaxNodeIdOffset = 20;

//! The header's maximum node id: the highest stream id in the file. The player sizes its stream
//! table from it, so a value below the ids the file's records use makes the whole file
//! unplayable. nullopt when the file is shorter than a header or does not start with "NI10" (an
//! OpenNI 1 or foreign file). Never throws.
std::optional<std::uint32_t> read_max_node_id(const std::filesystem::path& file);

//! Raises the header's maximum node id to at least `streams` in place, without touching anything
//! else (the recorder may be appending to the file meanwhile). Returns false when the file has no
//! NI10 header yet or cannot be written.
bool ensure_max_node_id(const std::filesystem::path& file, std::uint32_t streams);

}  // namespace scanclean::oni

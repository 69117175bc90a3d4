#pragma once
//! \file recording_source.h
//! The recorder as a decorator (STYLE.md practice 7): a RangeSource that forwards another source
//! unchanged and writes every frame it delivers to a recording folder (format v1). The pipeline
//! cannot tell which source it has.

#include <filesystem>
#include <memory>

#include "scanclean/core/range_source.h"
#include "scanclean/replay/recording_writer.h"

namespace scanclean {

//! Wraps `inner`. open() opens inner and, if inner.info().K has a size, creates the recording
//! (RecordingWriter on `folder`, session_from_info(inner info, K.width, K.height)); otherwise the
//! recording is created at the first delivered frame with that frame's depth size. Every kOk
//! frame of next() is written before it is returned (the frame itself is returned unchanged).
//! kTimeout/kDisconnected/kError are forwarded untouched. End of stream and close() finish()
//! the recording (session.json "finalized": true); a later open() (reconnect) appends to the same
//! recording. Destroying the source finishes the recording too (it then holds exactly the frames
//! that were delivered). When a reconnected inner source restarts its frame indices, the recorded
//! index is shifted so that it keeps increasing (the delivered frame keeps the inner index). info()
//! is the inner source's info. \throw whatever inner throws, plus RecordingWriter's
//! IoError/InputError (e.g. the folder already holds a recording, a frame of another size).
//! Thread safety: one thread per source object.
std::unique_ptr<RangeSource> make_recording_source(std::unique_ptr<RangeSource> inner,
                                                   const std::filesystem::path& folder,
                                                   const RecordingWriterOptions& options = {});

}  // namespace scanclean

#pragma once
//! \file replay.h
//! Everything scanclean::replay offers, in one include (the APIS.md "replay" contract).

#include "scanclean/replay/depth_image_source.h"
#include "scanclean/replay/recording_format.h"
#include "scanclean/replay/recording_reader.h"
#include "scanclean/replay/recording_source.h"
#include "scanclean/replay/recording_writer.h"
#include "scanclean/replay/replay_source.h"

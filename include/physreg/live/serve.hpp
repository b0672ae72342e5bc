// SPDX-License-Identifier: GPL-3.0-or-later
#pragma once
// The live link (issue 44; issue 59 item 6: a layer of the library above registration/): a served
// body model over OpenIGTLink. A TCP server that a tracker or a navigation display (3D Slicer's
// OpenIGTLinkIF, PLUS) connects to, or a client of a PlusServer: each TRANSFORM named after the tool
// moves the body model by condensed contact (paper 000; the latest pose wins), answered as POLYDATA
// per organ surface and POINT targets; a POLYDATA cloud is registered by paper 001's pipeline and an
// IMAGE segmentation by paper 002's, in the background while tool updates go on. `physreg serve`,
// Python's physreg.serve and a navigation system that embeds the library all call serve().
#include "physreg/registration/compression/compression_registration.hpp"
#include "physreg/registration/surface/partial_surface_registration.hpp"

#include <functional>
#include <string>

namespace physreg::live {

struct ServeOptions {
    std::string model;                         ///< a folder made by `physreg prepare` (starts in seconds), or
    std::string dataset;                       ///< a phantom dataset, prepared at start
    std::string parameters;                    ///< with `dataset`: a parameter file from `physreg estimate`
    std::string host = "127.0.0.1";            ///< address to listen on (loopback unless told: OpenIGTLink has no authentication)
    int port = 0;                              ///< TCP port to listen on, or
    std::string client;                        ///< HOST:PORT of a PlusServer to connect to instead
    int max_clients = 4;                       ///< connections served at once; more are refused with a STATUS
    double queue_mib = 64.0;                   ///< per client: MiB of answers waiting before model updates are dropped for it
    std::string frame = "ras";                 ///< coordinates on the wire: ras (3D Slicer's) or lps
    std::string tool = "tool";                 ///< device name of the tool's TRANSFORM
    std::string cloud = "cloud";               ///< device name of intra-operative clouds (POLYDATA)
    std::string segmentation = "segmentation"; ///< device name of intra-operative segmentations (IMAGE, labels)
    std::string record;                        ///< a file to record every message in and out (JSON lines; `physreg replay` reads it)
    double surface_cell_size = PartialSurfaceSettings{}.cell_size; ///< paper 001's liver model for clouds, mm
    bool once = false;                         ///< stop when the first client leaves (tests, scripts)
    /// Polled about every 100 ms on the serving thread: true ends the session cleanly (clients'
    /// queues flushed, connections closed). Python's Ctrl-C, an embedding program's shutdown.
    std::function<bool()> stop_requested;
};

/// Error naming the option for an impossible combination (a model and a dataset, a port and a
/// client, a port outside 1 … 65535, no client slot, a queue ≤ 0, a frame other than ras/lps).
void validate(const ServeOptions& options);

/// Serves until the session ends (`once`: the first client left; client mode: the server closed)
/// or SIGINT/SIGTERM arrives (then physreg::Interrupted). Blocks the calling thread; the model is
/// read or prepared first (Error naming the folder or dataset when it cannot be).
void serve(const ServeOptions& options, const CompressionRegistrationSettings& settings);

} // namespace physreg::live

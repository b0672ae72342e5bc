// SPDX-License-Identifier: GPL-3.0-or-later
// physreg serve: the options of the live link (physreg/live/serve.hpp) parsed and handed to the
// library, which holds the OpenIGTLink wire and the session.
#include "cli_support.hpp"
#include "physreg/live/serve.hpp"
#include "settings_options.hpp"

namespace physreg::cli {

void add_subcommand_serve(CLI::App& app)
{
    auto o = std::make_shared<live::ServeOptions>();
    auto* sub = app.add_subcommand("serve", "Paper 000 live over OpenIGTLink: tool poses (TRANSFORM) in, the body model's organ surfaces "
                                            "(POLYDATA) and targets (POINT) out, by condensed contact");
    sub->add_option("model", o->model, "A model made by physreg prepare (starts in seconds)");
    sub->add_option("--dataset", o->dataset, "Instead of MODEL, a phantom dataset: the body at rest, its landmarks, the tool and the session's paths "
                                             "(the model is prepared at start: about a minute on cirs057a)");
    sub->add_option("--parameters", o->parameters, "Parameter file from physreg estimate (else the model settings)");
    auto settings = std::make_shared<SettingsOptions<CompressionRegistrationSettings>>(sub, compression_spec());
    sub->add_option("--port", o->port, "TCP port to listen on (Slicer and PLUS default to 18944; give it only when asked)");
    sub->add_option("--client", o->client, "Client mode: connect to HOST:PORT (a PlusServer streaming the tracker's poses) instead of listening; "
                                           "the session ends when that server closes the connection");
    sub->add_option("--bind,--host", o->host, "Address to listen on (default 127.0.0.1, this machine only; 0.0.0.0 for every interface: "
                                              "OpenIGTLink has no authentication, see the README)");
    sub->add_option("--max-clients", o->max_clients, "Connections served at once (default 4); more are refused with a STATUS");
    sub->add_option("--send-queue", o->queue_mib, "Per client: MiB of answers waiting to be sent before new ones are dropped for it (default 64)");
    sub->add_option("--frame", o->frame, "Coordinates on the wire: ras (3D Slicer's, default) or lps (the images')");
    sub->add_option("--tool", o->tool, "Device name of the tool's TRANSFORM (default 'tool'); other transforms are ignored");
    sub->add_option("--record", o->record, "Write every message in and out (type, device, timestamp, wall time; the bytes of those in) as JSON "
                                           "lines: physreg replay sends such a session again");
    sub->add_option("--cloud", o->cloud, "Device name of the intra-operative clouds (POLYDATA points; default 'cloud'): each one is registered by "
                                         "paper 001's pipeline in the background while tool updates go on, the latest cloud winning");
    sub->add_option("--segmentation", o->segmentation, "Device name of intra-operative segmentations (IMAGE, 8- or 16-bit labels as the "
                                                       "dataset's): each is registered by paper 002's pipeline in the background (default 'segmentation'); "
                                                       "the organ surfaces and targets come back as <organ>_segmentation and targets_segmentation");
    sub->add_option("--surface-cell-size", o->surface_cell_size, "Paper 001's tetrahedral liver model for clouds: largest circumradius, mm (default 7)");
    sub->add_flag("--once", o->once, "Stop when the first client disconnects (tests, scripts)");
    sub->callback([o, settings] { live::serve(*o, settings->resolve()); });
}

} // namespace physreg::cli

// SPDX-License-Identifier: GPL-3.0-or-later
// physreg replay (issue 44): a tracker session played to an OpenIGTLink server at its own pace —
// the messages a `serve --record` file received, or a phantom dataset's tool paths as TRANSFORMs at
// a given rate — with the answers read back and the end-to-end latency measured per answered pose
// (send → the POINT answer carrying the pose's timestamp).
#include "cli_support.hpp"
#include "physreg/live/igtl_wire.hpp"

#include "physreg/core/atomic_file.hpp"
#include "physreg/core/error.hpp"
#include "physreg/core/log.hpp"
#include "physreg/io/dataset.hpp"
#include "physreg/registration/compression/compression_registration.hpp"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <thread>

namespace physreg::cli {
using namespace live; // the OpenIGTLink wire (physreg/live/igtl_wire.hpp)

namespace {

struct Scheduled {
    double at_s = 0.0;                 ///< from the session's start
    std::vector<std::uint8_t> bytes;
    std::uint64_t timestamp = 0;
    bool pose = false;                 ///< a TRANSFORM (its answer is timed)
};

std::vector<Scheduled> from_recording(const std::string& file)
{
    std::ifstream in(file);
    if (!in) fail("replay: recording '{}' cannot be read", file);
    std::vector<Scheduled> out;
    std::string line;
    int number = 0;
    while (std::getline(in, line)) {
        ++number;
        if (line.empty()) continue;
        const std::string where = fmt::format("recording '{}' line {}", file, number);
        nlohmann::json j;
        try {
            j = nlohmann::json::parse(line);
        } catch (const std::exception& e) {
            fail("{}: not JSON: {}", where, e.what());
        }
        if (j.value("direction", "") != "in" || !j.contains("bytes_hex")) continue;
        Scheduled s;
        s.at_s = j.at("wall_s").get<double>();
        s.bytes = from_hex(j.at("bytes_hex").get<std::string>(), where);
        const IgtlMessage m = parse_igtl_message(s.bytes); // checks the message before anything is sent
        s.timestamp = m.timestamp;
        s.pose = m.type == "TRANSFORM";
        out.push_back(std::move(s));
    }
    if (out.empty()) fail("replay: recording '{}' holds no message received by the server", file);
    const double first = out.front().at_s;
    for (auto& s : out) s.at_s -= first;
    return out;
}

/// The dataset's tool paths, first contact to final position, `steps` poses each, at `rate` Hz.
std::vector<Scheduled> from_dataset(const std::string& directory, const std::string& states, int steps, double rate, const std::string& tool,
                                    double wire)
{
    const PhantomDataset dataset = read_phantom_dataset(directory);
    std::vector<Scheduled> out;
    std::uint32_t index = 0;
    for (const auto& name : split_names(states, "--states")) {
        const auto& state = dataset.state(name);
        if (!state.tool) fail("--states: '{}' is not a tool compression", name);
        const Vec3 a = state.tool->path.front(), b = state.tool->path.back();
        for (int k = 0; k <= steps; ++k) {
            const Vec3 x = a + (b - a) * (double(k) / steps);
            ++index;
            Scheduled s;
            s.at_s = double(out.size()) / rate;
            // A pose's number as its time: unique, so that answers find their pose.
            s.bytes = transform_message(tool, x, wire, std::uint64_t(index) << 32);
            s.timestamp = std::uint64_t(index) << 32;
            s.pose = true;
            out.push_back(std::move(s));
        }
    }
    return out;
}

} // namespace

void add_subcommand_replay(CLI::App& app)
{
    struct Options : CommonOptions {
        std::string recording, to, dataset, states = "A", tool = "tool", frame = "ras", output;
        int steps = 20;
        double rate = 30.0, speed = 1.0, linger = 2.0;
    };
    auto o = std::make_shared<Options>();
    auto* sub = app.add_subcommand("replay", "Play a tracker session to an OpenIGTLink server (physreg serve) at its own pace: a serve --record "
                                             "file, or a phantom dataset's tool paths; the answers' end-to-end latency measured");
    sub->add_option("recording", o->recording, "A recording from physreg serve --record (else --dataset)");
    sub->add_option("--to", o->to, "The server, HOST:PORT")->required();
    sub->add_option("--dataset", o->dataset, "Instead of a recording: the tool paths of this phantom dataset's compressions");
    sub->add_option("--states", o->states, "With --dataset: the compressions whose paths are played (default A)");
    sub->add_option("--steps", o->steps, "With --dataset: poses per path after the first contact (default 20)");
    sub->add_option("--rate", o->rate, "With --dataset: poses per second (default 30)");
    sub->add_option("--tool", o->tool, "With --dataset: the transforms' device name (default 'tool')");
    sub->add_option("--frame", o->frame, "With --dataset: ras (default, 3D Slicer's) or lps");
    sub->add_option("--speed", o->speed, "Pace: 1 the recorded one, 2 twice as fast (default 1)");
    sub->add_option("--linger", o->linger, "Seconds to wait for the last answers after the last message (default 2)");
    sub->add_option("-o,--output", o->output, "Write the summary (JSON) here");
    sub->add_flag("--json", o->json, "Print the summary as JSON on stdout");
    sub->callback([o] {
        if (o->recording.empty() == o->dataset.empty()) fail("replay: give a recording or --dataset, one of them");
        if (!(o->speed > 0)) fail("--speed {} must be > 0", o->speed);
        if (!(o->rate > 0)) fail("--rate {} must be > 0 poses per second", o->rate);
        if (o->steps < 1) fail("--steps {} must be ≥ 1", o->steps);
        if (!(o->linger >= 0)) fail("--linger {} must be ≥ 0 s", o->linger);
        if (o->frame != "ras" && o->frame != "lps") fail("--frame '{}': use ras or lps", o->frame);
        if (!o->output.empty()) check_output_path(o->output, "--output");
        const auto session = o->recording.empty() ? from_dataset(o->dataset, o->states, o->steps, o->rate, o->tool, o->frame == "ras" ? -1.0 : 1.0)
                                                  : from_recording(o->recording);
        Descriptor server(connect_to(o->to, "--to"));
        using clock = std::chrono::steady_clock;
        const auto start = clock::now();
        const auto since = [&] { return std::chrono::duration<double>(clock::now() - start).count(); };
        std::map<std::uint64_t, double> sent_at; // pose timestamp → send time, s
        std::vector<double> latency_ms;
        std::map<std::string, int> answers;
        std::uint64_t last_answered = 0;
        bool gone = false;
        const auto read_answers = [&](double until_s) {
            while (!gone) {
                const double left = until_s - since();
                if (!more_waiting(server.get(), std::max(0, static_cast<int>(left * 1000.0)))) {
                    if (since() >= until_s) return;
                    continue;
                }
                const auto m = read_igtl_message(server.get());
                if (!m) {
                    gone = true;
                    return;
                }
                ++answers[m->type];
                if (m->type == "POINT") {
                    const auto it = sent_at.find(m->timestamp);
                    if (it != sent_at.end()) latency_ms.push_back(1000.0 * (since() - it->second));
                    last_answered = m->timestamp;
                }
            }
        };
        int poses = 0;
        for (const auto& s : session) {
            read_answers(s.at_s / o->speed);
            if (gone) fail("replay: the server closed the connection after {} poses", poses);
            if (s.pose) sent_at[s.timestamp] = since(), ++poses;
            if (!send_all(server.get(), s.bytes.data(), s.bytes.size())) fail("replay: the server went away after {} poses", poses);
        }
        read_answers(since() + o->linger);
        std::vector<double> sorted = latency_ms;
        std::sort(sorted.begin(), sorted.end());
        const auto quantile = [&](double q) { return sorted.empty() ? 0.0 : sorted[static_cast<std::size_t>(q * double(sorted.size() - 1))]; };
        nlohmann::json summary = {{"messages_sent", session.size()},
                                  {"poses_sent", poses},
                                  {"poses_answered", latency_ms.size()},
                                  {"answers", answers},
                                  {"last_pose_answered", !session.empty() && last_answered == session.back().timestamp},
                                  {"latency_ms", {{"median", quantile(0.5)}, {"p95", quantile(0.95)}, {"max", sorted.empty() ? 0.0 : sorted.back()}}},
                                  {"seconds", since()},
                                  {"what", "latency: a pose sent → the POINT answer carrying its timestamp; poses sent while one was solved are "
                                           "dropped by the server (the latest wins), so fewer are answered than sent"}};
        std::cerr << fmt::format("replay: {} poses sent, {} answered; latency median {:.2f} ms, 95 % {:.2f} ms, max {:.2f} ms\n", poses,
                                 latency_ms.size(), quantile(0.5), quantile(0.95), sorted.empty() ? 0.0 : sorted.back());
        if (!o->output.empty()) write_atomically(o->output, [&](const std::filesystem::path& tmp) { std::ofstream(tmp) << summary.dump(2) << "\n"; });
        if (o->json) std::cout << summary.dump(2) << std::endl;
    });
}

} // namespace physreg::cli

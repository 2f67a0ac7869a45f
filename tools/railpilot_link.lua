-- railpilot_link.lua: Wireshark / tshark dissector for the railpilot train-ground link.
--
-- Written from docs/protocol.md (the byte-exact specification, version 1), not from the
-- Python code. Section numbers below refer to that document.
--
-- Load it for one run:
--     tshark -X lua_script:tools/railpilot_link.lua -r capture.pcapng -V
-- or copy it into the personal Lua plugins folder (Wireshark: Help > About > Folders >
-- "Personal Lua Plugins", usually ~/.local/lib/wireshark/plugins/).
--
-- Transport: TCP. The specification leaves the port to deployment configuration (section
-- 1), so this dissector picks 7400 as its default. Change it with the preference
--     railpilot.tcp_port   (Edit > Preferences > Protocols > RAILPILOT, or
--                           tshark -o railpilot.tcp_port:NNNN)
-- or with "Decode As" (tshark -d tcp.port==NNNN,railpilot).
-- Preference railpilot.max_frame_length is the receiver's frame length limit (default 2048,
-- section 3 and 9).
--
-- What it does:
--   * TCP stream: frames may be split over segments and one segment may hold several
--     frames; the dissector asks TCP for more data (desegment_offset/desegment_len) until
--     the number of *unstuffed* bytes given by the length field has arrived. The on-wire
--     size differs from the length field by the number of doubled 0x7E bytes, so the frame
--     end is found by unstuffing while counting (section 3).
--   * Receiver rules of section 3: hunting for a single 0x7E (bytes skipped are shown as
--     discarded), version and length checked after the first 4 unstuffed bytes, a lone 0x7E
--     inside a frame cuts it short (framing error) and starts the next frame.
--   * Every header field (section 4), the body of every message type (section 6) with raw
--     wire values, units and scaled SI values, range checks of section 6 (expert info on a
--     value out of range), the CRC-32 (section 4.1) recomputed and compared (expert info on
--     mismatch). The HMAC (section 4.2) needs the train's key, which a capture does not
--     have: the 128-bit tag is shown, not verified.
--   * Stateful checks (sequence, timestamp order, delay, state; section 5.4 #14-17) need the
--     connection history and are not judged here.
--
-- Display filter fields: railpilot.type, railpilot.src, railpilot.dst, railpilot.seq,
-- railpilot.crc.status (0 Bad, 1 Good), railpilot.flags.auth, railpilot.<message>.<field>
-- (e.g. railpilot.running_info.speed, railpilot.tsr_set.session); experts railpilot.crc.bad,
-- railpilot.framing, railpilot.length.bad, railpilot.body.bad, ...
--
-- Works with the Lua 5.2 of Wireshark 3.x/4.0 and the Lua 5.3/5.4 of later releases.

local DEFAULT_TCP_PORT = 7400
local DEFAULT_MAX_FRAME_LENGTH = 2048

local HEADER_BYTE = 0x7E
local HEADER_CHAR = "\126"
local PREFIX_LENGTH = 4
local HEADER_LENGTH = 35
local MAC_LENGTH = 16
local CRC_LENGTH = 4
local MIN_FRAME_LENGTH = HEADER_LENGTH + CRC_LENGTH
local PROTOCOL_VERSION = 1
local FLAG_AUTH = 1

-- ---------------------------------------------------------------------------------------
-- Bit operations and CRC-32/ISO-HDLC (poly 0x04C11DB7 reflected = 0xEDB88320, init and
-- xor-out 0xFFFFFFFF): the same as zlib.crc32.

local band, bxor, rshift
if _VERSION == "Lua 5.3" or _VERSION == "Lua 5.4" then
    -- Native operators; compiled from a string so Lua 5.2 never parses them.
    band, bxor, rshift = load([[
        return function(a, b) return a & b end,
               function(a, b) return a ~ b end,
               function(a, n) return a >> n end
    ]])()
elseif bit32 then
    band, bxor, rshift = bit32.band, bit32.bxor, bit32.rshift
else -- LuaBitOp (results are signed 32-bit)
    band = function(a, b) return bit.band(a, b) % 4294967296 end
    bxor = function(a, b) return bit.bxor(a, b) % 4294967296 end
    rshift = function(a, n) return bit.rshift(a, n) % 4294967296 end
end

local CRC_TABLE = {}
for i = 0, 255 do
    local c = i
    for _ = 1, 8 do
        if c % 2 == 1 then
            c = bxor(rshift(c, 1), 0xEDB88320)
        else
            c = rshift(c, 1)
        end
    end
    CRC_TABLE[i] = c
end

local function crc32(s)
    local c = 0xFFFFFFFF
    for i = 1, #s do
        c = bxor(CRC_TABLE[band(bxor(c, s:byte(i)), 0xFF)], rshift(c, 8))
    end
    return bxor(c, 0xFFFFFFFF)
end

-- ---------------------------------------------------------------------------------------
-- Catalogue (section 6)

local MSG = {
    [0x01] = "REGISTER_REQUEST",
    [0x02] = "REGISTER_RESPONSE",
    [0x03] = "DEREGISTER_REQUEST",
    [0x04] = "DEREGISTER_RESPONSE",
    [0x10] = "TIME_CHECK",
    [0x11] = "TIME_OFFSET_REPORT",
    [0x20] = "RUNNING_INFO",
    [0x21] = "STATION_STOPS",
    [0x22] = "RUNNING_TIMES",
    [0x23] = "PLANNED_CURVE",
    [0x24] = "TARGET_POINT",
    [0x25] = "TARGET_POINT_ACK",
    [0x30] = "TSR_SET",
    [0x31] = "TSR_SET_ACK",
    [0x32] = "TSR_CANCEL",
    [0x33] = "TSR_CANCEL_ACK",
    [0x40] = "DISPATCH_COMMAND",
    [0x41] = "DISPATCH_ACK",
    [0x50] = "HEARTBEAT",
}

local UP, DOWN, BOTH = "onboard -> ground", "ground -> onboard", "both directions"
local MSG_DIRECTION = {
    [0x01] = UP, [0x02] = DOWN, [0x03] = UP, [0x04] = DOWN, [0x10] = DOWN, [0x11] = UP,
    [0x20] = UP, [0x21] = DOWN, [0x22] = DOWN, [0x23] = UP, [0x24] = DOWN, [0x25] = UP,
    [0x30] = DOWN, [0x31] = UP, [0x32] = DOWN, [0x33] = UP, [0x40] = DOWN, [0x41] = UP,
    [0x50] = BOTH,
}

-- Fixed body lengths; false = variable (checked by the body decoder).
local BODY_LENGTH = {
    [0x01] = 24, [0x02] = 1, [0x03] = 1, [0x04] = 1, [0x10] = 8, [0x11] = 24, [0x20] = 27,
    [0x21] = false, [0x22] = false, [0x23] = 16, [0x24] = 9, [0x25] = 5, [0x30] = 30,
    [0x31] = 5, [0x32] = 4, [0x33] = 5, [0x40] = false, [0x41] = 5, [0x50] = 0,
}

local VS_REGISTER_RESULT = { [0] = "ACCEPTED", [1] = "UNKNOWN_TRAIN", [2] = "REFUSED" }
local VS_DEREGISTER_REASON = {
    [1] = "SHUNTING_MODE", [2] = "MANUAL_SHUTDOWN", [3] = "LEAVING_MAIN_LINE",
}
local VS_DEREGISTER_RESULT = { [0] = "DEREGISTERED" }
local VS_DIRECTION = { [0] = "UNKNOWN", [1] = "UP", [2] = "DOWN" }
local VS_TARGET_REASON = {
    [1] = "TRAIN_AHEAD", [2] = "SWITCH_INDICATION_LOST", [3] = "SECTION_FAULT", [255] = "OTHER",
}
local VS_TARGET_RESULT = { [0] = "ACCEPTED", [1] = "REJECTED" }
local VS_TSR_SET_RESULT = { [0] = "APPLIED", [1] = "INVALID", [2] = "EXPIRED" }
local VS_TSR_CANCEL_RESULT = { [0] = "CANCELLED", [1] = "UNKNOWN_SESSION" }
local VS_DISPATCH_RESULT = { [0] = "RECEIVED" }
local VS_CRC_STATUS = { [0] = "Bad", [1] = "Good" }

-- Range limits (section 6)
local MAX_POSITION_CM = 1000000000 -- 10^9 cm
local MAX_SPEED_CMS = 10000
local MAX_TRAIN_LENGTH_CM = 1000000
local MAX_LIST_ENTRIES = 64
local MAX_TEXT_BYTES = 1000
local MAX_EPOCH_US = UInt64.fromhex("002386f26fc10000") -- 10^16 us
local MAX_OFFSET_US = Int64.fromhex("000000e8d4a51000") -- 10^12 us

-- ---------------------------------------------------------------------------------------
-- Protocol, preferences, fields, expert info

local railpilot = Proto("railpilot", "railpilot train-ground link")

railpilot.prefs.tcp_port = Pref.uint("TCP port", DEFAULT_TCP_PORT,
    "TCP port of the link (the ground front server's port); 0 = none (use Decode As)")
railpilot.prefs.max_frame_length = Pref.uint("Maximum frame length", DEFAULT_MAX_FRAME_LENGTH,
    "Receiver limit for the length field in unstuffed bytes (55..65535, section 9)")

local pf = {}
local function field(key, ctor, abbr, name, ...)
    pf[key] = ctor("railpilot." .. abbr, name, ...)
end

-- Framing and header
field("header_byte", ProtoField.uint8, "header_byte", "Header byte", base.HEX)
field("wire_length", ProtoField.uint32, "wire_length",
    "Bytes on the wire (header byte + stuffed frame)", base.DEC)
field("stuffed", ProtoField.uint32, "stuffed_bytes", "Stuffing bytes (doubled 0x7E)", base.DEC)
field("garbage", ProtoField.bytes, "discarded", "Discarded bytes (hunting for a header)")
field("truncated", ProtoField.bytes, "truncated", "Truncated frame")
field("version", ProtoField.uint8, "version", "Version", base.DEC)
field("flags", ProtoField.uint8, "flags", "Flags", base.HEX)
field("flag_auth", ProtoField.bool, "flags.auth", "AUTH (key id and MAC present)", 8, nil, 0x01)
field("flag_reserved", ProtoField.uint8, "flags.reserved", "Reserved bits", base.HEX, nil, 0xFE)
field("length", ProtoField.uint16, "length", "Length (unstuffed bytes, version to CRC)", base.DEC)
field("type", ProtoField.uint8, "type", "Message type", base.HEX, MSG)
field("direction", ProtoField.string, "direction", "Message direction")
field("key_id", ProtoField.uint16, "key_id", "Key id", base.DEC)
field("src", ProtoField.uint32, "src", "Source id", base.DEC)
field("dst", ProtoField.uint32, "dst", "Destination id", base.DEC)
field("seq", ProtoField.uint32, "seq", "Sequence number", base.DEC)
field("timestamp", ProtoField.uint64, "timestamp", "Timestamp [us since the epoch]", base.DEC)
field("timestamp_abs", ProtoField.absolute_time, "timestamp.time", "Timestamp", base.UTC)
field("echo", ProtoField.uint64, "echo", "Echo timestamp [us since the epoch]", base.DEC)
field("echo_abs", ProtoField.absolute_time, "echo.time", "Echo timestamp", base.UTC)
field("body", ProtoField.bytes, "body", "Body")
field("body_length", ProtoField.uint16, "body_length", "Body length", base.DEC)
field("mac", ProtoField.bytes, "mac", "MAC (HMAC-SHA256, first 16 bytes)")
field("crc", ProtoField.uint32, "crc", "CRC-32", base.HEX)
field("crc_computed", ProtoField.uint32, "crc.computed", "CRC-32 computed", base.HEX)
field("crc_status", ProtoField.uint8, "crc.status", "CRC-32 status", base.DEC, VS_CRC_STATUS)

-- Bodies (section 6). Raw wire integers keep the wire unit; *_m, *_s, *_mps fields are
-- generated SI values.
field("rr_train", ProtoField.string, "register_request.train_number", "Train number")
field("rr_loco", ProtoField.string, "register_request.loco_number", "Loco number")
field("rr_driver", ProtoField.uint32, "register_request.driver_id", "Driver id", base.DEC)
field("rr_length", ProtoField.uint32, "register_request.train_length", "Train length [cm]",
    base.DEC)
field("rr_length_m", ProtoField.double, "register_request.train_length_m", "Train length [m]")
field("rresp_result", ProtoField.uint8, "register_response.result", "Result", base.DEC,
    VS_REGISTER_RESULT)
field("dreq_reason", ProtoField.uint8, "deregister_request.reason", "Reason", base.DEC,
    VS_DEREGISTER_REASON)
field("dresp_result", ProtoField.uint8, "deregister_response.result", "Result", base.DEC,
    VS_DEREGISTER_RESULT)
field("tc_ground", ProtoField.uint64, "time_check.ground_time", "Ground time [us]", base.DEC)
field("tc_ground_abs", ProtoField.absolute_time, "time_check.ground_time.time", "Ground time",
    base.UTC)
field("to_ground", ProtoField.uint64, "time_offset_report.ground_time", "Ground time [us]",
    base.DEC)
field("to_ground_abs", ProtoField.absolute_time, "time_offset_report.ground_time.time",
    "Ground time", base.UTC)
field("to_onboard", ProtoField.uint64, "time_offset_report.onboard_time",
    "Onboard time [us]", base.DEC)
field("to_onboard_abs", ProtoField.absolute_time, "time_offset_report.onboard_time.time",
    "Onboard time", base.UTC)
field("to_offset", ProtoField.int64, "time_offset_report.offset",
    "Offset onboard - ground [us]", base.DEC)
field("to_offset_s", ProtoField.double, "time_offset_report.offset_s", "Offset [s]")
field("ri_driver", ProtoField.uint32, "running_info.driver_id", "Driver id", base.DEC)
field("ri_train", ProtoField.string, "running_info.train_number", "Train number")
field("ri_loco", ProtoField.string, "running_info.loco_number", "Loco number")
field("ri_dir", ProtoField.uint8, "running_info.direction", "Direction", base.DEC, VS_DIRECTION)
field("ri_speed", ProtoField.uint16, "running_info.speed", "Speed [cm/s]", base.DEC)
field("ri_speed_mps", ProtoField.double, "running_info.speed_mps", "Speed [m/s]")
field("ri_speed_kmh", ProtoField.double, "running_info.speed_kmh", "Speed [km/h]")
field("ri_pos", ProtoField.uint32, "running_info.position", "Position (km post) [cm]", base.DEC)
field("ri_pos_m", ProtoField.double, "running_info.position_m", "Position (km post) [m]")
field("ss_count", ProtoField.uint8, "station_stops.count", "Number of stops", base.DEC)
field("ss_station", ProtoField.uint32, "station_stops.station_id", "Station id", base.DEC)
field("ss_pos", ProtoField.uint32, "station_stops.position", "Stop position [cm]", base.DEC)
field("ss_pos_m", ProtoField.double, "station_stops.position_m", "Stop position [m]")
field("ss_dwell", ProtoField.uint16, "station_stops.dwell", "Dwell time [s]", base.DEC)
field("rt_count", ProtoField.uint8, "running_times.count", "Number of entries", base.DEC)
field("rt_from", ProtoField.uint32, "running_times.from_station", "From station id", base.DEC)
field("rt_to", ProtoField.uint32, "running_times.to_station", "To station id", base.DEC)
field("rt_time", ProtoField.uint32, "running_times.time", "Planned running time [ms]",
    base.DEC)
field("rt_time_s", ProtoField.double, "running_times.time_s", "Planned running time [s]")
field("pc_from", ProtoField.uint32, "planned_curve.from_station", "From station id", base.DEC)
field("pc_to", ProtoField.uint32, "planned_curve.to_station", "To station id", base.DEC)
field("pc_elapsed", ProtoField.uint32, "planned_curve.elapsed", "Elapsed time [ms]", base.DEC)
field("pc_elapsed_s", ProtoField.double, "planned_curve.elapsed_s", "Elapsed time [s]")
field("pc_remaining", ProtoField.uint32, "planned_curve.remaining", "Remaining time [ms]",
    base.DEC)
field("pc_remaining_s", ProtoField.double, "planned_curve.remaining_s", "Remaining time [s]")
field("tp_id", ProtoField.uint32, "target_point.target_id", "Target id", base.DEC)
field("tp_pos", ProtoField.uint32, "target_point.position",
    "Position (red signal km post) [cm]", base.DEC)
field("tp_pos_m", ProtoField.double, "target_point.position_m",
    "Position (red signal km post) [m]")
field("tp_reason", ProtoField.uint8, "target_point.reason", "Reason", base.DEC, VS_TARGET_REASON)
field("tpa_id", ProtoField.uint32, "target_point_ack.target_id", "Target id", base.DEC)
field("tpa_result", ProtoField.uint8, "target_point_ack.result", "Result", base.DEC,
    VS_TARGET_RESULT)
field("tsr_session", ProtoField.uint32, "tsr_set.session", "Session number", base.DEC)
field("tsr_start", ProtoField.uint32, "tsr_set.start", "Start km post [cm]", base.DEC)
field("tsr_start_m", ProtoField.double, "tsr_set.start_m", "Start km post [m]")
field("tsr_end", ProtoField.uint32, "tsr_set.end", "End km post [cm]", base.DEC)
field("tsr_end_m", ProtoField.double, "tsr_set.end_m", "End km post [m]")
field("tsr_limit", ProtoField.uint16, "tsr_set.limit", "Speed limit [cm/s]", base.DEC)
field("tsr_limit_mps", ProtoField.double, "tsr_set.limit_mps", "Speed limit [m/s]")
field("tsr_limit_kmh", ProtoField.double, "tsr_set.limit_kmh", "Speed limit [km/h]")
field("tsr_from", ProtoField.uint64, "tsr_set.valid_from", "Valid from [us]", base.DEC)
field("tsr_from_abs", ProtoField.absolute_time, "tsr_set.valid_from.time", "Valid from",
    base.UTC)
field("tsr_until", ProtoField.uint64, "tsr_set.valid_until", "Valid until [us]", base.DEC)
field("tsr_until_abs", ProtoField.absolute_time, "tsr_set.valid_until.time", "Valid until",
    base.UTC)
field("tsra_session", ProtoField.uint32, "tsr_set_ack.session", "Session number", base.DEC)
field("tsra_result", ProtoField.uint8, "tsr_set_ack.result", "Result", base.DEC,
    VS_TSR_SET_RESULT)
field("tsrc_session", ProtoField.uint32, "tsr_cancel.session", "Session number", base.DEC)
field("tsrca_session", ProtoField.uint32, "tsr_cancel_ack.session", "Session number",
    base.DEC)
field("tsrca_result", ProtoField.uint8, "tsr_cancel_ack.result", "Result", base.DEC,
    VS_TSR_CANCEL_RESULT)
field("dc_number", ProtoField.uint32, "dispatch_command.number", "Command number", base.DEC)
field("dc_text_len", ProtoField.uint16, "dispatch_command.text_length", "Text length [bytes]",
    base.DEC)
field("dc_text", ProtoField.string, "dispatch_command.text", "Text", base.UNICODE)
field("da_number", ProtoField.uint32, "dispatch_ack.number", "Command number", base.DEC)
field("da_result", ProtoField.uint8, "dispatch_ack.result", "Result", base.DEC,
    VS_DISPATCH_RESULT)

local field_list = {}
for _, f in pairs(pf) do
    field_list[#field_list + 1] = f
end
railpilot.fields = field_list

local ex = {
    crc = ProtoExpert.new("railpilot.crc.bad", "CRC-32 mismatch (crc check)",
        expert.group.CHECKSUM, expert.severity.ERROR),
    framing = ProtoExpert.new("railpilot.framing",
        "Frame cut short by a header byte (framing check)",
        expert.group.MALFORMED, expert.severity.ERROR),
    version = ProtoExpert.new("railpilot.version.bad", "Version check failed",
        expert.group.PROTOCOL, expert.severity.ERROR),
    length = ProtoExpert.new("railpilot.length.bad", "Length check failed",
        expert.group.MALFORMED, expert.severity.ERROR),
    auth = ProtoExpert.new("railpilot.auth.bad", "AUTH flag and key id inconsistent (auth check)",
        expert.group.SECURITY, expert.severity.ERROR),
    unauth = ProtoExpert.new("railpilot.auth.none",
        "Frame not authenticated (rejected where authentication is required)",
        expert.group.SECURITY, expert.severity.NOTE),
    type = ProtoExpert.new("railpilot.type.unknown", "Unknown message type (type check)",
        expert.group.PROTOCOL, expert.severity.ERROR),
    body = ProtoExpert.new("railpilot.body.bad", "Body field out of range (body check)",
        expert.group.PROTOCOL, expert.severity.ERROR),
    garbage = ProtoExpert.new("railpilot.hunting", "Bytes discarded while hunting for a header",
        expert.group.PROTOCOL, expert.severity.WARN),
}
railpilot.experts = { ex.crc, ex.framing, ex.version, ex.length, ex.auth, ex.unauth, ex.type,
    ex.body, ex.garbage }

-- ---------------------------------------------------------------------------------------
-- Helpers

-- char[8] (section 2): 1..8 bytes 0x21..0x7E, right-padded with 0x00.
local function ident(range)
    local s = range:raw()
    local text = s:gsub("%z+$", "")
    local ok = #text >= 1
    for i = 1, #text do
        local b = text:byte(i)
        if b < 0x21 or b > 0x7E then
            ok = false
        end
    end
    return text, ok
end

local function add_ident(tree, f, range)
    local text, ok = ident(range)
    local item = tree:add(f, range, text)
    if not ok then
        item:add_proto_expert_info(ex.body,
            "char[8] must be 1 to 8 characters 0x21..0x7E padded with 0x00")
    end
    return text
end

local function valid_utf8(s)
    local i, n = 1, #s
    while i <= n do
        local c = s:byte(i)
        local extra, min
        if c < 0x80 then
            extra, min = 0, 0
        elseif c >= 0xC2 and c <= 0xDF then
            extra, min = 1, 0x80
        elseif c >= 0xE0 and c <= 0xEF then
            extra, min = 2, 0x800
        elseif c >= 0xF0 and c <= 0xF4 then
            extra, min = 3, 0x10000
        else
            return false
        end
        if i + extra > n then
            return false
        end
        local cp = c % (2 ^ (6 - extra + (extra == 0 and 1 or 0)))
        for k = 1, extra do
            local cc = s:byte(i + k)
            if cc < 0x80 or cc > 0xBF then
                return false
            end
            cp = cp * 64 + (cc - 0x80)
        end
        if extra > 0 and (cp < min or cp > 0x10FFFF or (cp >= 0xD800 and cp <= 0xDFFF)) then
            return false
        end
        i = i + extra + 1
    end
    return true
end

local function nstime_of_us(u64)
    local secs = (u64 / 1000000):tonumber()
    local usec = (u64 % 1000000):tonumber()
    return NSTime.new(secs, usec * 1000)
end

-- u64 us since the epoch, with its absolute time; range 0..10^16 (section 6).
local function add_epoch_us(tree, f_raw, f_abs, range, checked)
    local v = range:uint64()
    tree:add(f_raw, range)
    tree:add(f_abs, range, nstime_of_us(v)):set_generated()
    if checked and v > MAX_EPOCH_US then
        tree:add_proto_expert_info(ex.body, "time out of range 0..10^16 us")
    end
    return v
end

local function add_scaled(tree, f_raw, f_si, range, scale, unit_fmt, max, min)
    local v = range:uint()
    local item = tree:add(f_raw, range)
    item:append_text(string.format(unit_fmt, v / scale, v / 100000))
    tree:add(f_si, range, v / scale):set_generated()
    if (max and v > max) or (min and v < min) then
        item:add_proto_expert_info(ex.body, string.format("value %d outside [%d, %d]",
            v, min or 0, max))
    end
    return v
end

local function add_enum(tree, f, range, vs)
    local v = range:uint()
    local item = tree:add(f, range)
    if vs[v] == nil then
        item:add_proto_expert_info(ex.body, string.format("unknown enum value %d", v))
    end
    return v
end

local function add_nonzero_u32(tree, f, range)
    local v = range:uint()
    local item = tree:add(f, range)
    if v == 0 then
        item:add_proto_expert_info(ex.body, "session/command number 0 is invalid (1..2^32-1)")
    end
    return v
end

-- ---------------------------------------------------------------------------------------
-- Body decoders: function(tree, body_tvb_range, body_length) -> short summary for Info

local BODY = {}

BODY[0x01] = function(t, b)
    local train = add_ident(t, pf.rr_train, b(0, 8))
    add_ident(t, pf.rr_loco, b(8, 8))
    t:add(pf.rr_driver, b(16, 4))
    add_scaled(t, pf.rr_length, pf.rr_length_m, b(20, 4), 100, " (%.2f m)", MAX_TRAIN_LENGTH_CM)
    return "train " .. train
end

BODY[0x02] = function(t, b)
    local v = add_enum(t, pf.rresp_result, b(0, 1), VS_REGISTER_RESULT)
    return VS_REGISTER_RESULT[v] or tostring(v)
end

BODY[0x03] = function(t, b)
    local v = add_enum(t, pf.dreq_reason, b(0, 1), VS_DEREGISTER_REASON)
    return VS_DEREGISTER_REASON[v] or tostring(v)
end

BODY[0x04] = function(t, b)
    local v = add_enum(t, pf.dresp_result, b(0, 1), VS_DEREGISTER_RESULT)
    return VS_DEREGISTER_RESULT[v] or tostring(v)
end

BODY[0x10] = function(t, b)
    add_epoch_us(t, pf.tc_ground, pf.tc_ground_abs, b(0, 8), true)
end

BODY[0x11] = function(t, b)
    add_epoch_us(t, pf.to_ground, pf.to_ground_abs, b(0, 8), true)
    add_epoch_us(t, pf.to_onboard, pf.to_onboard_abs, b(8, 8), true)
    local off = b(16, 8):int64()
    local item = t:add(pf.to_offset, b(16, 8))
    local off_s = off:tonumber() / 1e6
    item:append_text(string.format(" (%.6f s)", off_s))
    t:add(pf.to_offset_s, b(16, 8), off_s):set_generated()
    if off > MAX_OFFSET_US or off < -MAX_OFFSET_US then
        item:add_proto_expert_info(ex.body, "offset outside -10^12..10^12 us")
    elseif off ~= b(8, 8):int64() - b(0, 8):int64() then  -- both < 2^63: signed is exact
        -- section 6.6: the offset is exactly onboard time - ground time
        item:add_proto_expert_info(ex.body, "offset is not onboard time - ground time")
    end
    return string.format("offset %.6f s", off_s)
end

BODY[0x20] = function(t, b)
    t:add(pf.ri_driver, b(0, 4))
    add_ident(t, pf.ri_train, b(4, 8))
    add_ident(t, pf.ri_loco, b(12, 8))
    local dir = add_enum(t, pf.ri_dir, b(20, 1), VS_DIRECTION)
    local speed = add_scaled(t, pf.ri_speed, pf.ri_speed_mps, b(21, 2), 100,
        " (%.2f m/s)", MAX_SPEED_CMS)
    t:add(pf.ri_speed_kmh, b(21, 2), speed * 0.036):set_generated()
    local pos = add_scaled(t, pf.ri_pos, pf.ri_pos_m, b(23, 4), 100, " (%.2f m, km post %.5f)",
        MAX_POSITION_CM)
    return string.format("%s %.2f m/s at km %.5f", VS_DIRECTION[dir] or "?", speed / 100,
        pos / 100000)
end

local function list_count(t, b, len, f_count, entry)
    local count = b(0, 1):uint()
    local item = t:add(f_count, b(0, 1))
    -- section 5.4 #13: a count the body length contradicts is a length failure; a count
    -- that fits the body but exceeds the maximum is a body (range) failure
    if len ~= 1 + entry * count then
        item:add_proto_expert_info(ex.length, string.format(
            "%d entries need a body of %d bytes, got %d", count, 1 + entry * count, len))
        return nil
    end
    if count > MAX_LIST_ENTRIES then
        item:add_proto_expert_info(ex.body, string.format(
            "%d entries; at most %d allowed", count, MAX_LIST_ENTRIES))
        return nil
    end
    return count
end

BODY[0x21] = function(t, b, len)
    if len < 1 then
        t:add_proto_expert_info(ex.length, "list body is empty; expected a count byte")
        return nil
    end
    local count = list_count(t, b, len, pf.ss_count, 10)
    if count == nil then
        return nil
    end
    for i = 0, count - 1 do
        local e = b(1 + 10 * i, 10)
        local st = t:add(e, string.format("Stop %d", i + 1))
        local sid = e(0, 4):uint()
        st:add(pf.ss_station, e(0, 4))
        local pos = add_scaled(st, pf.ss_pos, pf.ss_pos_m, e(4, 4), 100,
            " (%.2f m, km post %.5f)", MAX_POSITION_CM)
        st:add(pf.ss_dwell, e(8, 2))
        st:append_text(string.format(": station %d at %.2f m, dwell %d s", sid, pos / 100,
            e(8, 2):uint()))
    end
    return string.format("%d stops", count)
end

BODY[0x22] = function(t, b, len)
    if len < 1 then
        t:add_proto_expert_info(ex.length, "list body is empty; expected a count byte")
        return nil
    end
    local count = list_count(t, b, len, pf.rt_count, 12)
    if count == nil then
        return nil
    end
    for i = 0, count - 1 do
        local e = b(1 + 12 * i, 12)
        local st = t:add(e, string.format("Running time %d", i + 1))
        st:add(pf.rt_from, e(0, 4))
        st:add(pf.rt_to, e(4, 4))
        local ms = add_scaled(st, pf.rt_time, pf.rt_time_s, e(8, 4), 1000, " (%.3f s)")
        st:append_text(string.format(": %d -> %d, %.3f s", e(0, 4):uint(), e(4, 4):uint(),
            ms / 1000))
    end
    return string.format("%d entries", count)
end

BODY[0x23] = function(t, b)
    t:add(pf.pc_from, b(0, 4))
    t:add(pf.pc_to, b(4, 4))
    add_scaled(t, pf.pc_elapsed, pf.pc_elapsed_s, b(8, 4), 1000, " (%.3f s)")
    add_scaled(t, pf.pc_remaining, pf.pc_remaining_s, b(12, 4), 1000, " (%.3f s)")
end

BODY[0x24] = function(t, b)
    local id = b(0, 4):uint()
    t:add(pf.tp_id, b(0, 4))
    local pos = add_scaled(t, pf.tp_pos, pf.tp_pos_m, b(4, 4), 100, " (%.2f m, km post %.5f)",
        MAX_POSITION_CM)
    local reason = add_enum(t, pf.tp_reason, b(8, 1), VS_TARGET_REASON)
    return string.format("target %d at %.2f m, %s", id, pos / 100,
        VS_TARGET_REASON[reason] or "?")
end

local function id_result(f_id, f_result, vs, nonzero, what)
    return function(t, b)
        local id
        if nonzero then
            id = add_nonzero_u32(t, f_id, b(0, 4))
        else
            id = b(0, 4):uint()
            t:add(f_id, b(0, 4))
        end
        local r = add_enum(t, f_result, b(4, 1), vs)
        return string.format("%s %d %s", what, id, vs[r] or tostring(r))
    end
end

BODY[0x25] = id_result(pf.tpa_id, pf.tpa_result, VS_TARGET_RESULT, false, "target")
BODY[0x31] = id_result(pf.tsra_session, pf.tsra_result, VS_TSR_SET_RESULT, true, "session")
BODY[0x33] = id_result(pf.tsrca_session, pf.tsrca_result, VS_TSR_CANCEL_RESULT, true, "session")
BODY[0x41] = id_result(pf.da_number, pf.da_result, VS_DISPATCH_RESULT, true, "command")

BODY[0x30] = function(t, b)
    local session = add_nonzero_u32(t, pf.tsr_session, b(0, 4))
    local s = add_scaled(t, pf.tsr_start, pf.tsr_start_m, b(4, 4), 100, " (%.2f m, km post %.5f)",
        MAX_POSITION_CM)
    local e = add_scaled(t, pf.tsr_end, pf.tsr_end_m, b(8, 4), 100, " (%.2f m, km post %.5f)",
        MAX_POSITION_CM)
    local limit = add_scaled(t, pf.tsr_limit, pf.tsr_limit_mps, b(12, 2), 100, " (%.2f m/s)",
        MAX_SPEED_CMS, 1)
    t:add(pf.tsr_limit_kmh, b(12, 2), limit * 0.036):set_generated()
    add_epoch_us(t, pf.tsr_from, pf.tsr_from_abs, b(14, 8), true)
    add_epoch_us(t, pf.tsr_until, pf.tsr_until_abs, b(22, 8), true)
    return string.format("session %d, %.2f-%.2f m, %.1f km/h", session, s / 100, e / 100,
        limit * 0.036)
end

BODY[0x32] = function(t, b)
    local session = add_nonzero_u32(t, pf.tsrc_session, b(0, 4))
    return string.format("session %d", session)
end

BODY[0x40] = function(t, b, len)
    if len < 6 then
        t:add_proto_expert_info(ex.length, string.format(
            "dispatch command body of %d bytes is shorter than 6", len))
        return nil
    end
    local number = add_nonzero_u32(t, pf.dc_number, b(0, 4))
    local tlen = b(4, 2):uint()
    local item = t:add(pf.dc_text_len, b(4, 2))
    if tlen > MAX_TEXT_BYTES or len ~= 6 + tlen then
        item:add_proto_expert_info(ex.length, string.format(
            "text length %d does not match body length %d (text at most %d bytes)",
            tlen, len, MAX_TEXT_BYTES))
        return nil
    end
    if tlen == 0 then
        t:add(pf.dc_text, b(4, 2), ""):set_generated()
    else
        local raw = b(6, tlen):raw()
        local ti = t:add_packet_field(pf.dc_text, b(6, tlen), ENC_UTF_8)
        if not valid_utf8(raw) then
            ti:add_proto_expert_info(ex.body, "text is not valid UTF-8")
        end
    end
    return string.format("command %d", number)
end

BODY[0x50] = function()
end

-- ---------------------------------------------------------------------------------------
-- One complete unstuffed frame

local function dissect_frame(ftvb, wire_range, stuffed, tree)
    local n = ftvb:len()
    local root = tree:add(railpilot, wire_range)
    root:add(pf.header_byte, wire_range(0, 1))
    root:add(pf.wire_length, wire_range, wire_range:len()):set_generated()
    root:add(pf.stuffed, wire_range, stuffed):set_generated()

    local h = root:add(ftvb(0, HEADER_LENGTH), "Header")
    local version = ftvb(0, 1):uint()
    h:add(pf.version, ftvb(0, 1))
    local flags = ftvb(1, 1):uint()
    local fi = h:add(pf.flags, ftvb(1, 1))
    fi:add(pf.flag_auth, ftvb(1, 1))
    fi:add(pf.flag_reserved, ftvb(1, 1))
    local auth = flags % 2 == FLAG_AUTH
    if flags >= 2 then
        fi:add_proto_expert_info(ex.version, "reserved flag bits 1-7 set (version check)")
    end
    if version ~= PROTOCOL_VERSION then
        h:add_proto_expert_info(ex.version, string.format("version %d", version))
    end
    local length = ftvb(2, 2):uint()
    local li = h:add(pf.length, ftvb(2, 2))
    if length ~= n then
        li:add_proto_expert_info(ex.length, string.format("length field %d, frame %d bytes",
            length, n))
    end
    local mtype = ftvb(4, 1):uint()
    local name = MSG[mtype]
    local ti = h:add(pf.type, ftvb(4, 1))
    if name == nil then
        ti:add_proto_expert_info(ex.type, string.format("unknown message type 0x%02x", mtype))
        name = string.format("UNKNOWN(0x%02x)", mtype)
    else
        h:add(pf.direction, ftvb(4, 1), MSG_DIRECTION[mtype]):set_generated()
    end
    local key_id = ftvb(5, 2):uint()
    local ki = h:add(pf.key_id, ftvb(5, 2))
    if auth ~= (key_id ~= 0) then
        ki:add_proto_expert_info(ex.auth, string.format("key id %d with AUTH flag %d",
            key_id, auth and 1 or 0))
    end
    local src, dst, seq = ftvb(7, 4):uint(), ftvb(11, 4):uint(), ftvb(15, 4):uint()
    h:add(pf.src, ftvb(7, 4))
    h:add(pf.dst, ftvb(11, 4))
    h:add(pf.seq, ftvb(15, 4))
    add_epoch_us(h, pf.timestamp, pf.timestamp_abs, ftvb(19, 8), false)
    local echo = ftvb(27, 8):uint64()
    local ei = h:add(pf.echo, ftvb(27, 8))
    if echo == UInt64.new(0) then
        ei:append_text(" (none yet)")
    else
        h:add(pf.echo_abs, ftvb(27, 8), nstime_of_us(echo)):set_generated()
    end

    local body_end = n - CRC_LENGTH - (auth and MAC_LENGTH or 0)
    local body_len = body_end - HEADER_LENGTH
    local summary
    if body_len < 0 then
        root:add_proto_expert_info(ex.length, string.format(
            "frame of %d bytes too short for its header%s and CRC", n, auth and ", MAC" or ""))
    else
        local expected = BODY_LENGTH[mtype]
        local bt
        if body_len > 0 then
            bt = root:add(pf.body, ftvb(HEADER_LENGTH, body_len))
            bt:set_text(string.format("%s body (%d bytes)", name, body_len))
        else
            bt = root:add(ftvb(HEADER_LENGTH, 0), string.format("%s body (empty)", name))
        end
        bt:add(pf.body_length, ftvb(2, 2), body_len):set_generated()
        if expected and body_len ~= expected then
            bt:add_proto_expert_info(ex.length, string.format(
                "%s needs a %d-byte body, got %d", name, expected, body_len))
        elseif BODY[mtype] then
            local b = body_len > 0 and ftvb(HEADER_LENGTH, body_len) or nil
            summary = BODY[mtype](bt, b, body_len)
        end
        if auth then
            local mi = root:add(pf.mac, ftvb(body_end, MAC_LENGTH))
            mi:append_text(string.format(" (key id %d; not verified: needs the train's key)",
                key_id))
        else
            root:add_proto_expert_info(ex.unauth)
        end
    end

    local crc = ftvb(n - CRC_LENGTH, 4):uint()
    local computed = crc32(ftvb:raw(0, n - CRC_LENGTH))
    local ci = root:add(pf.crc, ftvb(n - CRC_LENGTH, 4))
    local good = crc == computed
    root:add(pf.crc_computed, ftvb(n - CRC_LENGTH, 4), computed):set_generated()
    root:add(pf.crc_status, ftvb(n - CRC_LENGTH, 4), good and 1 or 0):set_generated()
    if good then
        ci:append_text(" [correct]")
    else
        ci:append_text(string.format(" [incorrect, should be 0x%08x]", computed))
        ci:add_proto_expert_info(ex.crc, string.format(
            "CRC-32 0x%08x does not match the frame (computed 0x%08x)", crc, computed))
    end

    local text = string.format("%s %d->%d seq=%d", name, src, dst, seq)
    if summary then
        text = text .. " " .. summary
    end
    if auth then
        text = text .. " [AUTH]"
    end
    if not good then
        text = text .. " [CRC BAD]"
    end
    root:append_text(", " .. text)
    return text
end

-- ---------------------------------------------------------------------------------------
-- Stream: hunting, unstuffing, desegmentation (section 3)

-- Read `need` unstuffed bytes from raw (0-based offset `start`).
-- Returns "ok", bytes, end_offset, stuffed_count | "more" | "cut", offset_of_lone_header
local function unstuff(raw, start, need)
    local parts = {}
    local got, stuffed = 0, 0
    local i = start
    local n = #raw
    while got < need do
        if i >= n then
            return "more"
        end
        local j = raw:find(HEADER_CHAR, i + 1, true) -- 1-based index of the next 0x7E
        local plain_end = j and (j - 2) or (n - 1) -- last 0-based plain byte before it
        local take = math.min(need - got, plain_end - i + 1)
        if take > 0 then
            parts[#parts + 1] = raw:sub(i + 1, i + take)
            got = got + take
            i = i + take
        elseif j then -- raw byte at 0-based i is 0x7E
            if i + 1 >= n then
                return "more"
            end
            if raw:byte(i + 2) ~= HEADER_BYTE then
                return "cut", i
            end
            parts[#parts + 1] = HEADER_CHAR
            got = got + 1
            stuffed = stuffed + 1
            i = i + 2
        end
    end
    return "ok", table.concat(parts), i, stuffed
end

-- The unstuffed frame: the wire bytes themselves when nothing was stuffed (so the fields
-- highlight in the packet bytes), else a new data source "Unstuffed railpilot frame".
local function frame_tvb(tvb, start, stop, stuffed, unstuffed)
    if stuffed == 0 then
        return tvb(start, stop - start):tvb()
    end
    return ByteArray.new(unstuffed, true):tvb("Unstuffed railpilot frame")
end

function railpilot.dissector(tvb, pinfo, tree)
    local n = tvb:len()
    if n == 0 then
        return 0
    end
    local raw = tvb:raw(0, n)
    local max_len = math.max(MIN_FRAME_LENGTH + MAC_LENGTH,
        math.min(65535, railpilot.prefs.max_frame_length))
    local infos = {}
    local pos = 0
    local garbage_start = nil
    local need_more_at = nil

    local function flush_garbage(upto)
        if garbage_start and upto > garbage_start then
            local gi = tree:add(railpilot, tvb(garbage_start, upto - garbage_start))
            gi:set_text(string.format("railpilot: %d byte(s) discarded while hunting",
                upto - garbage_start))
            gi:add(pf.garbage, tvb(garbage_start, upto - garbage_start))
            gi:add_proto_expert_info(ex.garbage)
            infos[#infos + 1] = string.format("[%d bytes discarded]", upto - garbage_start)
        end
        garbage_start = nil
    end

    while pos < n do
        -- Hunting (rule 1)
        local j = raw:find(HEADER_CHAR, pos + 1, true)
        if j == nil then
            garbage_start = garbage_start or pos
            pos = n
            break
        end
        local h = j - 1
        if h > pos then
            garbage_start = garbage_start or pos
        end
        if h + 1 >= n then -- cannot yet tell a header from half a stuffed pair
            need_more_at = h
            break
        end
        if raw:byte(h + 2) == HEADER_BYTE then -- stuffed byte of a frame we missed
            garbage_start = garbage_start or pos
            pos = h + 2
        else
            flush_garbage(h)
            -- Rule 2: first 4 unstuffed bytes
            local st, prefix = unstuff(raw, h + 1, PREFIX_LENGTH)
            if st == "more" then
                need_more_at = h
                break
            elseif st == "cut" then
                local ci = tree:add(railpilot, tvb(h, prefix - h))
                ci:set_text("railpilot: truncated frame (framing error)")
                ci:add(pf.truncated, tvb(h, prefix - h))
                ci:add_proto_expert_info(ex.framing, "frame truncated by a header byte")
                infos[#infos + 1] = "[framing error]"
                pos = prefix
            else
                local version = prefix:byte(1)
                local length = prefix:byte(3) * 256 + prefix:byte(4)
                if version ~= PROTOCOL_VERSION or length < MIN_FRAME_LENGTH
                    or length > max_len then
                    local bi = tree:add(railpilot, tvb(h, 1))
                    bi:set_text(string.format("railpilot: rejected header (version %d, length %d)",
                        version, length))
                    bi:add(pf.header_byte, tvb(h, 1))
                    if version ~= PROTOCOL_VERSION then
                        bi:add_proto_expert_info(ex.version, string.format(
                            "version %d (this dissector speaks 1); resuming the hunt", version))
                        infos[#infos + 1] = "[version error]"
                    else
                        bi:add_proto_expert_info(ex.length, string.format(
                            "length field %d outside [%d, %d]; resuming the hunt", length,
                            MIN_FRAME_LENGTH, max_len))
                        infos[#infos + 1] = "[length error]"
                    end
                    pos = h + 1
                    garbage_start = pos
                else
                    -- Rule 3/4: the whole frame
                    local st2, frame, stop, stuffed = unstuff(raw, h + 1, length)
                    if st2 == "more" then
                        need_more_at = h
                        break
                    elseif st2 == "cut" then
                        local ci = tree:add(railpilot, tvb(h, frame - h))
                        ci:set_text("railpilot: truncated frame (framing error)")
                        ci:add(pf.truncated, tvb(h, frame - h))
                        ci:add_proto_expert_info(ex.framing, string.format(
                            "frame of %d bytes truncated by a header byte", length))
                        infos[#infos + 1] = "[framing error]"
                        pos = frame
                    else
                        local ftvb = frame_tvb(tvb, h + 1, stop, stuffed, frame)
                        infos[#infos + 1] = dissect_frame(ftvb, tvb(h, stop - h), stuffed, tree)
                        pos = stop
                    end
                end
            end
        end
    end
    flush_garbage(need_more_at or pos)

    if #infos > 0 then
        pinfo.cols.protocol = "RAILPILOT"
        pinfo.cols.info = table.concat(infos, ", ")
    end
    if need_more_at ~= nil then
        pinfo.desegment_offset = need_more_at
        pinfo.desegment_len = DESEGMENT_ONE_MORE_SEGMENT
    end
    return n
end

-- ---------------------------------------------------------------------------------------
-- Registration

local registered_port = 0

local function register_port()
    local tcp = DissectorTable.get("tcp.port")
    if registered_port ~= 0 then
        tcp:remove(registered_port, railpilot)
    end
    registered_port = railpilot.prefs.tcp_port
    if registered_port ~= 0 then
        tcp:add(registered_port, railpilot)
    end
end

function railpilot.prefs_changed()
    if railpilot.prefs.tcp_port ~= registered_port then
        register_port()
    end
end

register_port()

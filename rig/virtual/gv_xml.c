// rig/virtual/gv_xml.c — the virtual camera's GenICam description: Aravis's built-in
// fake camera XML edited into ours, and the in-process fake devices made from it.
#include <stdio.h>
#include <string.h>

#include "rig/camera/pixfmt.h"
#include "rig/virtual/internal.h"

// ---------------------------------------------------------------------------
// GenICam XML: Aravis's built-in fake camera description, edited.

// Replace the first `find` after the first `after` (NULL: from the start).
static bool xml_edit(GString *x, const char *after, const char *find, const char *repl)
{
    const char *from = x->str;
    if (after) {
        from = strstr(x->str, after);
        if (!from) return false;
    }
    const char *at = strstr(from, find);
    if (!at) return false;
    gssize pos = at - x->str;
    g_string_erase(x, pos, (gssize)strlen(find));
    g_string_insert(x, pos, repl);
    return true;
}

// Remove from `start` through the next `end`, plus the whitespace before start.
static bool xml_cut(GString *x, const char *start, const char *end)
{
    const char *s = strstr(x->str, start);
    if (!s) return false;
    const char *e = strstr(s, end);
    if (!e) return false;
    while (s > x->str && (s[-1] == ' ' || s[-1] == '\t' || s[-1] == '\n')) s--;
    g_string_erase(x, s - x->str, (e + strlen(end)) - s);
    return true;
}

static const char xml_added[] =
    "\n\t<!-- Added by refl rig/virtual/gv_camera.c -->\n"
    "\t<StringReg Name=\"DeviceSerialNumber\" NameSpace=\"Standard\">\n"
    "\t\t<DisplayName>Serial Number</DisplayName>\n"
    "\t\t<Address>0xd8</Address>\n\t\t<Length>16</Length>\n\t\t<AccessMode>RO</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t</StringReg>\n\n"
    "\t<Float Name=\"DeviceTemperature\" NameSpace=\"Standard\">\n"
    "\t\t<Description>Sensor temperature, degrees Celsius.</Description>\n"
    "\t\t<pValue>DeviceTemperatureReg</pValue>\n\t\t<Unit>C</Unit>\n\t</Float>\n\n"
    "\t<FloatReg Name=\"DeviceTemperatureReg\" NameSpace=\"Custom\">\n"
    "\t\t<Address>0xa018</Address>\n\t\t<Length>8</Length>\n\t\t<AccessMode>RO</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n"
    "\t<Float Name=\"ExposureTime\" NameSpace=\"Standard\">\n"
    "\t\t<Description>Exposure time, in microseconds.</Description>\n"
    "\t\t<pValue>ExposureTimeReg</pValue>\n\t\t<Min>10.0</Min>\n\t\t<Max>10000000.0</Max>\n"
    "\t\t<Unit>us</Unit>\n\t</Float>\n\n"
    "\t<FloatReg Name=\"ExposureTimeReg\" NameSpace=\"Custom\">\n"
    "\t\t<Address>0xa008</Address>\n\t\t<Length>8</Length>\n\t\t<AccessMode>RW</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n"
    "\t<Float Name=\"Gain\" NameSpace=\"Standard\">\n"
    "\t\t<Description>Analog gain, in dB.</Description>\n"
    "\t\t<pValue>GainReg</pValue>\n\t\t<Min>0.0</Min>\n\t\t<Max>24.0</Max>\n"
    "\t\t<Unit>dB</Unit>\n\t</Float>\n\n"
    "\t<FloatReg Name=\"GainReg\" NameSpace=\"Custom\">\n"
    "\t\t<Address>0xa010</Address>\n\t\t<Length>8</Length>\n\t\t<AccessMode>RW</AccessMode>\n"
    "\t\t<pPort>Device</pPort>\n\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n";

// The radiometric features (auto functions on by default, as on real cameras)
// and the transport's packet size and delay.
#define XML_AUTO_ENUM(name, desc, addr)                                                                 \
    "\t<Enumeration Name=\"" name "\" NameSpace=\"Standard\">\n"                                     \
    "\t\t<Description>" desc "</Description>\n"                                                       \
    "\t\t<EnumEntry Name=\"Off\" NameSpace=\"Standard\">\n\t\t\t<Value>0</Value>\n\t\t</EnumEntry>\n"     \
    "\t\t<EnumEntry Name=\"Once\" NameSpace=\"Standard\">\n\t\t\t<Value>1</Value>\n\t\t</EnumEntry>\n"    \
    "\t\t<EnumEntry Name=\"Continuous\" NameSpace=\"Standard\">\n\t\t\t<Value>2</Value>\n\t\t</EnumEntry>\n" \
    "\t\t<pValue>" name "Register</pValue>\n\t</Enumeration>\n\n"                                      \
    XML_INT_REG(name "Register", addr, "RW")
#define XML_INT_REG(name, addr, access)                                                                 \
    "\t<IntReg Name=\"" name "\" NameSpace=\"Custom\">\n\t\t<Address>" addr "</Address>\n"              \
    "\t\t<Length>4</Length>\n\t\t<AccessMode>" access "</AccessMode>\n\t\t<pPort>Device</pPort>\n"        \
    "\t\t<Sign>Unsigned</Sign>\n\t\t<Endianess>BigEndian</Endianess>\n\t</IntReg>\n\n"
#define XML_BOOL(name, desc, addr)                                                                      \
    "\t<Boolean Name=\"" name "\" NameSpace=\"Standard\">\n\t\t<Description>" desc "</Description>\n"   \
    "\t\t<pValue>" name "Register</pValue>\n\t\t<OnValue>1</OnValue>\n\t\t<OffValue>0</OffValue>\n"     \
    "\t</Boolean>\n\n" XML_INT_REG(name "Register", addr, "RW")
#define XML_FLOAT(name, desc, addr, min, max)                                                           \
    "\t<Float Name=\"" name "\" NameSpace=\"Standard\">\n\t\t<Description>" desc "</Description>\n"     \
    "\t\t<pValue>" name "Reg</pValue>\n\t\t<Min>" min "</Min>\n\t\t<Max>" max "</Max>\n\t</Float>\n\n"    \
    "\t<FloatReg Name=\"" name "Reg\" NameSpace=\"Custom\">\n\t\t<Address>" addr "</Address>\n"          \
    "\t\t<Length>8</Length>\n\t\t<AccessMode>RW</AccessMode>\n\t\t<pPort>Device</pPort>\n"               \
    "\t\t<Endianess>BigEndian</Endianess>\n\t</FloatReg>\n\n"
#define XML_INT(name, desc, reg, min, max, unit)                                                        \
    "\t<Integer Name=\"" name "\" NameSpace=\"Standard\">\n\t\t<Description>" desc "</Description>\n"   \
    "\t\t<pValue>" reg "</pValue>\n\t\t<Min>" min "</Min>\n\t\t<Max>" max "</Max>\n\t\t<Unit>" unit       \
    "</Unit>\n\t</Integer>\n\n"

static const char xml_radiometric[] =
    XML_AUTO_ENUM("ExposureAuto", "Automatic exposure: while on, frames are exposed 1.5 x ExposureTime.", "0xa020")
    XML_AUTO_ENUM("BalanceWhiteAuto", "Automatic white balance (a mono sensor ignores it).", "0xa024")
    XML_AUTO_ENUM("ContrastAuto", "A vendor's own automatic (not in the SFNC): found by a client only in the "
                  "feature tree; while on, frames get the LUT as with LUTEnable.", "0xa060")
    XML_BOOL("GammaEnable", "Gamma curve on the pixel values.", "0xa028")
    XML_FLOAT("Gamma", "The gamma of the curve v = max (v / max)^Gamma.", "0xa030", "0.1", "4.0")
    XML_BOOL("LUTEnable", "The camera's look-up table v = sqrt(v max) on the pixel values.", "0xa02c")
    XML_FLOAT("BlackLevel", "Black level, DN added to every pixel.", "0xa038", "0.0", "4095.0")
    "\t<StringReg Name=\"DeviceFirmwareVersion\" NameSpace=\"Standard\">\n\t\t<Address>0xa040</Address>\n"
    "\t\t<Length>32</Length>\n\t\t<AccessMode>RO</AccessMode>\n\t\t<pPort>Device</pPort>\n\t</StringReg>\n\n"
    XML_INT("GevSCPSPacketSize", "Stream channel 0 packet size, bytes (IP and UDP headers included).",
            "GevSCPSPacketSizeRegister", "576", "9000", "B")
    XML_INT_REG("GevSCPSPacketSizeRegister", "0xd04", "RW")
    XML_INT("GevSCPD", "Stream channel 0 delay between packets, timestamp ticks.", "GevSCPDRegister", "0",
            "1000000", "")
    XML_INT_REG("GevSCPDRegister", "0xd08", "RW");

// Guards Aravis's process-wide fake camera XML file name, which every new
// ArvFakeCamera reads (arv_set_fake_camera_genicam_filename is not thread safe).
static GMutex xml_name_lock;

// PixelFormat entries after Mono16: the formats of rig/camera/pixfmt.h the built-in
// XML lacks (Mono12 goes after Mono8, in rig_gv_xml_make). false when Mono16 is missing.
static bool xml_add_formats(GString *x)
{
    GString *e = g_string_new("</EnumEntry>");
    for (int f = 0; f < RIG_PIXFMT_COUNT; f++) {
        if (f == RIG_PIXFMT_MONO8 || f == RIG_PIXFMT_MONO12 || f == RIG_PIXFMT_MONO16) continue;
        g_string_append_printf(e, "\n\t\t<EnumEntry Name=\"%s\" NameSpace=\"Standard\">\n\t\t\t<Value>%u</Value>"
                               "\n\t\t</EnumEntry>", rig_pixfmt_name((rig_pixfmt_t)f),
                               (unsigned)rig_pixfmt_pfnc((rig_pixfmt_t)f));
    }
    bool ok = xml_edit(x, "<EnumEntry Name=\"Mono16\"", "</EnumEntry>", e->str);
    g_string_free(e, TRUE);
    return ok;
}

// The variants of the XML a camera's parameters ask for: the Gain's unit, an
// auto feature that cannot be switched off (no Off entry). false
// when the XML lacks what is edited.
static bool xml_variants(GString *x, const char *gain_unit, const char *refuse_off)
{
    if (strcmp(gain_unit, "dB")) {
        char unit[48] = "";
        if (*gain_unit) snprintf(unit, sizeof unit, "<Unit>%s</Unit>", gain_unit);
        if (!xml_edit(x, "<Float Name=\"Gain\"", "<Unit>dB</Unit>", unit)) return false;
    }
    if (*refuse_off) {   // its Off entry removed: it cannot be switched off
        char en[64];
        snprintf(en, sizeof en, "<Enumeration Name=\"%s\"", refuse_off);
        const char *e = strstr(x->str, en);
        const char *off = e ? strstr(e, "<EnumEntry Name=\"Off\"") : NULL;
        const char *end = off ? strstr(off, "</EnumEntry>") : NULL;
        const char *next = e ? strstr(e, "</Enumeration>") : NULL;
        if (!end || end > next) return false;
        g_string_erase(x, off - x->str, end + strlen("</EnumEntry>") - off);
    }
    return true;
}

// Our XML as a new string, or NULL with a message.
char *rig_gv_xml_make(const char *gain_unit, const char *refuse_off)
{
    g_mutex_lock(&xml_name_lock);
    ArvFakeCamera *tmp = arv_fake_camera_new("REFL-XML");   // no network: just the built-in XML
    g_mutex_unlock(&xml_name_lock);
    size_t size = 0;
    const char *base = tmp ? arv_fake_camera_get_genicam_xml(tmp, &size) : NULL;
    if (!base || !size) {
        if (tmp) g_object_unref(tmp);
        rig_fail(RIG_ERR_IO, "gv camera: Aravis's built-in fake camera XML is not available");
        return NULL;
    }
    GString *x = g_string_new_len(base, (gssize)size);
    g_object_unref(tmp);

    char mono12[160];
    snprintf(mono12, sizeof mono12,
             "</EnumEntry>\n\t\t<EnumEntry Name=\"Mono12\" NameSpace=\"Standard\">\n\t\t\t<Value>%u</Value>\n\t\t</EnumEntry>",
             (unsigned)ARV_PIXEL_FORMAT_MONO_12);
    const char *bad = NULL;
    // Root: make sure AnalogControl is reachable (0.8.26 leaves it out).
    {
        const char *root = strstr(x->str, "<Category Name=\"Root\"");
        const char *end = root ? strstr(root, "</Category>") : NULL;
        if (!end) bad = "Root category";
        else if (!g_strstr_len(root, end - root, "AnalogControl") &&
                 !xml_edit(x, "<Category Name=\"Root\"", "<pFeature>TransportLayerControl</pFeature>",
                           "<pFeature>AnalogControl</pFeature>\n\t\t<pFeature>TransportLayerControl</pFeature>"))
            bad = "Root/TransportLayerControl";
    }
    if (!bad && !xml_edit(x, NULL, "<pFeature>DeviceID</pFeature>",
                          "<pFeature>DeviceID</pFeature>\n\t\t<pFeature>DeviceSerialNumber</pFeature>"
                          "\n\t\t<pFeature>DeviceTemperature</pFeature>\n\t\t<pFeature>DeviceFirmwareVersion</pFeature>"))
        bad = "DeviceID feature";
    if (!bad && !xml_edit(x, "<Category Name=\"TransportLayerControl\"", "<pFeature>PayloadSize</pFeature>",
                          "<pFeature>PayloadSize</pFeature>\n\t\t<pFeature>GevSCPSPacketSize</pFeature>"
                          "\n\t\t<pFeature>GevSCPD</pFeature>"))
        bad = "TransportLayerControl/PayloadSize";
    if (!bad && !xml_edit(x, "<Category Name=\"AnalogControl\"", "<pFeature>GainAuto</pFeature>",
                          "<pFeature>GainAuto</pFeature>\n\t\t<pFeature>BalanceWhiteAuto</pFeature>"
                          "\n\t\t<pFeature>BlackLevel</pFeature>\n\t\t<pFeature>GammaEnable</pFeature>"
                          "\n\t\t<pFeature>Gamma</pFeature>\n\t\t<pFeature>LUTEnable</pFeature>"
                          "\n\t\t<pFeature>ContrastAuto</pFeature>"))
        bad = "AnalogControl/GainAuto";
    // Binning is not simulated: do not advertise it.
    if (!bad && !xml_cut(x, "<pFeature>BinningHorizontal</pFeature>", "</pFeature>")) bad = "BinningHorizontal";
    if (!bad && !xml_cut(x, "<pFeature>BinningVertical</pFeature>", "</pFeature>")) bad = "BinningVertical";
    // Monochrome formats only: those of rig/camera/pixfmt.h (Mono12 unpacked, the packed ones).
    static const char *const colour[] = { "BayerBG8", "BayerGB8", "BayerGR8", "BayerRG8", "RGB8" };
    for (size_t i = 0; !bad && i < sizeof colour / sizeof colour[0]; i++) {
        char start[64];
        snprintf(start, sizeof start, "<EnumEntry Name=\"%s\"", colour[i]);
        if (!xml_cut(x, start, "</EnumEntry>")) bad = colour[i];
    }
    if (!bad && !xml_edit(x, "<EnumEntry Name=\"Mono8\"", "</EnumEntry>", mono12)) bad = "Mono8 entry";
    if (!bad && !xml_add_formats(x)) bad = "Mono16 entry";
    // ExposureTime (float, us) replaces ExposureTimeAbs, which stays as an alias.
    if (!bad && !xml_edit(x, "<Category Name=\"AcquisitionControl\"", "<pFeature>ExposureTimeAbs</pFeature>",
                          "<pFeature>ExposureTime</pFeature>"))
        bad = "AcquisitionControl/ExposureTimeAbs";
    if (!bad && !xml_edit(x, "<Category Name=\"AcquisitionControl\"", "<pFeature>ExposureTime</pFeature>",
                          "<pFeature>ExposureTime</pFeature>\n\t\t<pFeature>ExposureAuto</pFeature>"))
        bad = "AcquisitionControl/ExposureTime";
    if (!bad && !xml_edit(x, "<Float Name=\"ExposureTimeAbs\"", "<pValue>ExposureTimeAbsConverter</pValue>",
                          "<pValue>ExposureTimeReg</pValue>"))
        bad = "ExposureTimeAbs";
    // TriggerSoftware goes to our register; the render thread forwards it.
    if (!bad && !xml_edit(x, "<IntReg Name=\"TriggerSoftwareCommandRegister\"", "<Address>0x30c</Address>",
                          "<Address>0xa000</Address>"))
        bad = "TriggerSoftwareCommandRegister";
    // Gain (float, dB) replaces GainRaw in AnalogControl.
    if (!bad && !xml_edit(x, "<Category Name=\"AnalogControl\"", "<pFeature>GainRaw</pFeature>",
                          "<pFeature>Gain</pFeature>"))
        bad = "AnalogControl/GainRaw";
    const char *end = bad ? NULL : strstr(x->str, "</RegisterDescription>");
    if (end) {
        gssize pos = end - x->str;
        g_string_insert(x, pos, xml_radiometric);
        g_string_insert(x, pos, xml_added);
    } else if (!bad) bad = "</RegisterDescription>";
    if (!bad && !xml_variants(x, gain_unit, refuse_off)) bad = "Gain unit or the register of the feature to refuse";
    if (bad) {
        g_string_free(x, TRUE);
        rig_fail(RIG_ERR_IO, "gv camera: Aravis %d.%d.%d's built-in fake camera XML has no %s where expected; "
                 "rig/virtual/gv_camera.c needs updating for this Aravis version",
                 arv_get_major_version(), arv_get_minor_version(), arv_get_micro_version(), bad);
        return NULL;
    }
    return g_string_free(x, FALSE);
}

// The ArvFakeDevice of an in-process server, with our XML.
ArvDevice *rig_gv_xml_fake_device(const char *serial, const char *xml_path, char *err, size_t errsize)
{
    GError *e = NULL;
    g_mutex_lock(&xml_name_lock);
    arv_set_fake_camera_genicam_filename(xml_path);   // read when the camera is made
    ArvDevice *dev = arv_fake_device_new(serial, &e);
    arv_set_fake_camera_genicam_filename(NULL);
    g_mutex_unlock(&xml_name_lock);
    if (!dev) snprintf(err, errsize, "%s", e ? e->message : "unknown error");
    g_clear_error(&e);
    return dev;
}
